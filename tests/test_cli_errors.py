"""Every `dronectl` command turns bad input into one line on stderr and a non-zero exit, creates nothing
and writes over nothing; `--debug` shows the traceback instead; third-party noise stays out.

Most cases call the command line in this process (`dronectl.cli.main`); the noise of a library that
prints when it loads needs a fresh process.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from dronectl.cli import main

from drone_inspect_core.files import CLAIM_MARKER, claimed_dir

REPO = Path(__file__).resolve().parents[1]


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, list[str]]:
    """(exit code, stderr lines) of `dronectl argv...` run here."""
    try:
        code = main(list(argv))
    except SystemExit as exc:  # argparse's own exit, as the console script would see it
        code = int(exc.code or 0)
    return code, capsys.readouterr().err.splitlines()


def test_help_prints_nothing_on_stderr_not_even_pybulletss_banner() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "dronectl", "sim-vehicle", "--help"], capture_output=True, text=True, cwd=REPO
    )
    assert done.returncode == 0 and "usage: dronectl sim-vehicle" in done.stdout
    assert done.stderr == ""


@pytest.mark.parametrize(
    ("argv", "fragment"),
    [
        (["fly", "--seed", "-5"], "argument --seed: must be >= 0"),
        (["train", "--data", "d", "--out", "o", "--epochs", "0"], "argument --epochs: must be >= 1"),
        (["move", "--right-m", "nan"], "MoveFlight.right_m must be a distance"),
        (["bench", "nope"], "unknown benchmark 'nope'"),
        (["fault-matrix", "--n", "0"], "argument --n: must be >= 1"),
        (["missions"], "the following arguments are required: action"),
    ],
)
def test_a_bad_option_is_one_line(capsys: pytest.CaptureFixture[str], argv: list[str], fragment: str) -> None:
    code, err = run(capsys, *argv)
    assert code == 2
    assert len(err) == 1 and fragment in err[0], err
    assert err[0].startswith("dronectl")


def test_an_error_no_command_caught_is_one_line_and_debug_shows_where(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    missing = tmp_path / "nothing"
    argv = ["train", "--data", str(missing), "--out", str(tmp_path / "run"), "--epochs", "1"]
    code, err = run(capsys, *argv)
    assert code == 1 and len(err) == 1 and err[0].startswith("dronectl train: ") and str(missing) in err[0]
    code, debug_err = run(capsys, "--debug", *argv)
    assert code == 1 and debug_err[0] == "Traceback (most recent call last):" and debug_err[-1] == err[0]


def test_a_command_that_names_its_own_errors_says_them_in_one_line(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    argv = ["evaluate", "--model", str(tmp_path / "nothing"), "--data", str(tmp_path / "nothing")]
    code, err = run(capsys, *argv)
    assert code == 1 and err == [f"dronectl evaluate: checkpoint folder not found: {tmp_path / 'nothing'}"]


def test_training_on_a_bad_dataset_leaves_no_run_folder(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    for command in ("train", "train-detector"):
        out = tmp_path / "runs" / command
        code, err = run(
            capsys, command, "--data", str(tmp_path / "missing"), "--out", str(out), "--epochs", "1"
        )
        assert code == 1 and len(err) == 1 and "no such dataset folder" in err[0]
        assert not (tmp_path / "runs").exists()


def test_a_result_file_is_never_written_over(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    kept = tmp_path / "result.json"
    kept.write_text("earlier numbers")
    code, err = run(capsys, "gym-eval", "--episodes", "1", "--json", str(kept))
    assert code == 2 and len(err) == 1 and "exists: a result is never written over" in err[0]
    assert kept.read_text() == "earlier numbers"


def test_a_claimed_folder_is_given_back_as_it_was_when_the_work_fails(tmp_path: Path) -> None:
    made = tmp_path / "a" / "b"
    with pytest.raises(RuntimeError), claimed_dir(made):
        raise RuntimeError("the work failed before writing anything")
    assert not (tmp_path / "a").exists()  # the folders the claim made are gone
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(RuntimeError), claimed_dir(empty):
        raise RuntimeError("failed")
    assert empty.is_dir() and not any(empty.iterdir())  # an empty folder that existed stays
    with claimed_dir(tmp_path / "ok") as folder:
        (folder / "result.txt").write_text("done")
    assert sorted(p.name for p in folder.iterdir()) == ["result.txt"]  # the claim released
    assert not (folder / CLAIM_MARKER).exists()


def test_runs_started_at_once_with_a_default_folder_each_get_their_own(tmp_path: Path) -> None:
    from drone_inspect_core.files import claim_fresh_dir

    base = tmp_path / "runs" / "fly" / "default-20261125-120000"
    first, second = claim_fresh_dir(base), claim_fresh_dir(base)  # the same default name, one second
    assert (first, second) == (base, base.with_name(base.name + "-2"))
