"""Distillation (`controller.training.distill`): a student learns a finished planner's scores.

The training test uses the SYNTHETIC fixture (tests/latent_synthetic.py): a teacher is trained on it
with the paper's losses, then a student with every one of those losses at 0, so that the teacher's
scores are all it learns from."""

from dataclasses import replace
from pathlib import Path

import pytest
import torch
from latent_synthetic import small_grounded, write_synthetic_dataset

from controller.evaluation.evaluate import evaluate_checkpoint
from controller.planning.latent.errors import PlannerCheckpointError
from controller.planning.latent.tokenizer import InstructionTokenizer
from controller.training.config import LossWeights, TrainConfig
from controller.training.distill import Teacher, presence_distillation, ranking_distillation
from controller.training.instructions import builtin_templates
from controller.training.pairs import DescriptionSampler
from controller.training.train import train


def test_the_ranking_term_is_zero_at_the_teachers_scores_and_leads_the_student_to_its_choice() -> None:
    gen = torch.Generator().manual_seed(0)
    teacher = torch.rand(8, 9, generator=gen) * 2.0
    assert float(ranking_distillation(teacher, teacher, 0.1)) == pytest.approx(0.0, abs=1e-6)
    student = (torch.rand(8, 9, generator=gen) * 2.0).requires_grad_(True)
    start = float(ranking_distillation(student, teacher, 0.1).detach())
    assert start > 0.1
    optimiser = torch.optim.SGD([student], lr=0.01)
    for _ in range(300):
        optimiser.zero_grad()
        ranking_distillation(student, teacher, 0.1).backward()
        optimiser.step()
    assert float(ranking_distillation(student, teacher, 0.1).detach()) < 0.05 * start
    assert torch.equal(student.argmin(dim=1), teacher.argmin(dim=1))  # the teacher's move, per sample
    empty = torch.zeros(0, 9, requires_grad=True)
    assert float(ranking_distillation(empty, empty, 0.1).detach()) == 0.0  # a batch with nothing in view


def test_the_presence_term_is_smallest_at_the_teachers_probability() -> None:
    teacher = torch.tensor([2.0, -1.0, 0.0])
    at = presence_distillation(teacher, teacher)
    for shift in (-1.0, 1.0):
        assert float(presence_distillation(teacher + shift, teacher)) > float(at)


def test_the_sampler_spells_each_instruction_in_the_teachers_tokens_too() -> None:
    """A teacher with another vocabulary reads the same sentence, in its own ids."""
    templates = builtin_templates("train")
    student = InstructionTokenizer.train(["center the gauge", "centre the valve now"], 160)
    teacher = InstructionTokenizer.train(["please line up on the switch box and the red valve"], 170)
    sampler = DescriptionSampler(student, templates, "train", 0.2, teacher_tokenizer=teacher)
    texts = list(sampler.row_of)
    assert sampler.teacher_ids is not None and not torch.equal(sampler.ids[:, :5], sampler.teacher_ids[:, :5])
    for row in (0, len(texts) // 2, len(texts) - 1):
        spelt = [teacher.token(int(i)) for i in sampler.teacher_ids[row] if int(i) != 0]
        own = [student.token(int(i)) for i in sampler.ids[row] if int(i) != 0]
        assert "".join(spelt).replace("##", "") == "".join(own).replace("##", "")
    assert DescriptionSampler(student, templates, "train", 0.2).teacher_ids is None


def test_distillation_is_refused_where_it_cannot_run(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="described"):
        TrainConfig(distill_from="somewhere")  # the named target choice has no sampled instructions
    with pytest.raises(ValueError, match="distill_weight"):
        TrainConfig(distill_weight=-1.0)
    with pytest.raises(PlannerCheckpointError, match="not found"):
        Teacher.load(tmp_path / "nothing", 128, torch.device("cpu"), channels_last=False)
    shipped = Path(__file__).resolve().parents[1] / "controller/planning/assets/latent_cpu"
    with pytest.raises(PlannerCheckpointError, match="64 px"):
        Teacher.load(shipped, 64, torch.device("cpu"), channels_last=False)


@pytest.mark.timeout(600)  # ~50 s on an idle core
def test_a_student_learns_the_moves_from_its_teachers_scores_alone(tmp_path: Path) -> None:
    """With the paper's four losses and the presence loss at 0, the student's only signal is the
    teacher's ranking of the moves: it must still rank them well above chance on held-out images (a
    student whose distillation term is lost stays at its first weights, near chance)."""
    data = write_synthetic_dataset(tmp_path / "data", n_goal=40, n_train=400, n_test=120, size=64, seed=3)
    model_cfg, base = small_grounded(epochs=15)
    train(data, tmp_path / "teacher", model_cfg, base, progress=False)
    taught = evaluate_checkpoint(tmp_path / "teacher", data, "heldout")
    assert taught.rank1 >= 0.6, taught.rank1  # a teacher worth learning from

    nothing_but_the_teacher = replace(
        base,
        weights=LossWeights(dir=0.0, rank=0.0, cons=0.0, reg=0.0),
        presence_weight=0.0,
        distill_from=str(tmp_path / "teacher"),
        seed=1,
        epochs=25,
    )
    train(data, tmp_path / "student", model_cfg, nothing_but_the_teacher, progress=False)
    learned = evaluate_checkpoint(tmp_path / "student", data, "heldout")
    # Measured: teacher 64 %, student 58 %; the same student without its teacher 7 %, and the majority
    # move 21 % of the test images.
    assert learned.rank1 >= 0.45, (learned.rank1, taught.rank1)
