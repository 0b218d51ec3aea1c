"""CPU inference through ONNX Runtime: pick a backend, export a torch module in memory, run it.

The networks are stored as safetensors checkpoints only; their ONNX graphs are exported from the
loaded torch module when a model is loaded (a fraction of a second, in memory, never written to or
read from disk), so no ONNX file is shipped or downloaded. ONNX Runtime is an optional extra
(`pip install -e '.[onnx]'`); this module is the only one that imports it, and it imports torch
only to export.

`resolve_backend("auto")` gives "onnx" when `onnxruntime` imports, else "torch" (logged either
way). `OnnxModule.export(module, inputs, ...)` checks the exported graph against the module on
the example inputs before it is used; a graph that disagrees raises `OnnxBackendError`.
"""

from __future__ import annotations

import io
import logging
import time
import warnings
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

log = logging.getLogger(__name__)

BACKENDS = ("torch", "onnx", "auto")
EXPORT_OPSET = 17
EXPORT_TOLERANCE = 1e-4  # largest |ONNX − torch| accepted on the example inputs


class OnnxBackendError(RuntimeError):
    """ONNX Runtime was asked for but is missing, or a model could not be exported or run with it."""


def onnxruntime_available() -> bool:
    """Whether onnxruntime imports (installed, and its shared libraries load)."""
    try:
        import onnxruntime  # noqa: F401
    except ImportError:
        return False
    return True


def resolve_backend(requested: str, what: str) -> str:
    """"torch" or "onnx" for `requested` in BACKENDS; `what` names the model in the log and errors."""
    if requested not in BACKENDS:
        raise ValueError(f"{what}: backend must be one of {BACKENDS}, got {requested!r}")
    if requested == "onnx" and not onnxruntime_available():
        raise OnnxBackendError(
            f"{what}: backend 'onnx' needs onnxruntime (pip install -e '.[onnx]'), which is not installed"
        )
    backend = requested
    if requested == "auto":
        backend = "onnx" if onnxruntime_available() else "torch"
        log.info("%s: backend auto -> %s (onnxruntime %s)", what, backend,
                 "installed" if backend == "onnx" else "not installed")  # fmt: skip
    return backend


def onnx_for(requested: str, what: str, export: Callable[[], OnnxModule]) -> OnnxModule | None:
    """The ONNX session `requested` asks for, or None to run on torch.

    "onnx" raises OnnxBackendError when onnxruntime is missing or `export()` fails; "auto" then
    falls back to torch with a warning.
    """
    if resolve_backend(requested, what) == "torch":
        return None
    try:
        return export()
    except OnnxBackendError as exc:
        if requested != "auto":
            raise
        log.warning("%s: %s; running on torch", what, exc)
        return None


class OnnxModule:
    """An ONNX Runtime session on one CPU thread pool: `run(*arrays) -> list of float32 arrays`."""

    def __init__(self, model_bytes: bytes, input_names: Sequence[str], threads: int | None = 1) -> None:
        import onnxruntime as ort

        options = ort.SessionOptions()
        options.intra_op_num_threads = threads or 0  # 0: ONNX Runtime's own choice
        options.inter_op_num_threads = 1
        options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        self.input_names = tuple(input_names)
        self._session = ort.InferenceSession(model_bytes, options, providers=["CPUExecutionProvider"])

    def run(self, *arrays: np.ndarray) -> list[np.ndarray]:
        named = zip(self.input_names, arrays, strict=True)
        feeds = {name: np.ascontiguousarray(a, dtype=np.float32) for name, a in named}
        return self._session.run(None, feeds)

    @classmethod
    def export(
        cls,
        module: Any,
        inputs: Sequence[Any],
        input_names: Sequence[str],
        output_names: Sequence[str],
        what: str,
        threads: int | None = 1,
    ) -> OnnxModule:
        """Export `module` (a torch nn.Module, eval mode) with a dynamic batch axis, run it, check it.

        `inputs` are example torch tensors; every input and output has the batch as its first axis.
        Raises OnnxBackendError naming `what` when the export fails or the graph's outputs differ
        from the module's by more than EXPORT_TOLERANCE on the examples.
        """
        import torch

        if module.training:  # the exporter would leave dropout and batch statistics switched on
            raise ValueError(f"{what}: export an eval-mode module")
        with torch.inference_mode():
            expected = module(*inputs)
        expected = expected if isinstance(expected, tuple) else (expected,)
        buffer = io.BytesIO()
        axes = {name: {0: "batch"} for name in (*input_names, *output_names)}
        try:
            with warnings.catch_warnings():  # the TorchScript exporter: no onnxscript needed, deprecated
                warnings.simplefilter("ignore", DeprecationWarning)
                torch.onnx.export(
                    module, tuple(inputs), buffer, dynamo=False, opset_version=EXPORT_OPSET,
                    input_names=list(input_names), output_names=list(output_names), dynamic_axes=axes,
                )  # fmt: skip
            session = cls(buffer.getvalue(), input_names, threads)
        except Exception as exc:  # the exporter and ONNX Runtime raise many kinds
            raise OnnxBackendError(f"{what}: ONNX export failed: {exc}") from exc
        got = session.run(*(t.detach().numpy() for t in inputs))
        for name, want, have in zip(output_names, expected, got, strict=True):
            error = float(np.max(np.abs(want.numpy() - have))) if have.size else 0.0
            if not error <= EXPORT_TOLERANCE:
                raise OnnxBackendError(f"{what}: ONNX output {name!r} differs from torch by {error:.3g}")
        log.debug("%s: exported to ONNX (%d bytes)", what, len(buffer.getvalue()))
        return session


def time_side_by_side(
    calls: dict[str, Callable[[int], object]], repeats: int, rounds: int = 4, warmup: int = 20
) -> dict[str, dict[str, float]]:
    """p50 / p99 / mean / max wall milliseconds of each backend's `call(i)` (i = 0, 1, ... picks the input).

    Each backend runs `repeats` calls in all, in `rounds` alternating blocks, so that the drift of a
    shared machine's speed falls on every backend alike. `cpu_p50_ms` / `cpu_p99_ms` are the calling
    thread's CPU time per call: the wall time less the time other processes held the core.
    """
    times: dict[str, list[float]] = {name: [] for name in calls}
    cpu: dict[str, list[float]] = {name: [] for name in calls}
    for call in calls.values():
        for i in range(warmup):
            call(i)
    per_round = max(1, repeats // rounds)
    for r in range(rounds):
        for name, call in calls.items():
            for i in range(r * per_round, (r + 1) * per_round):
                start, start_cpu = time.perf_counter(), time.thread_time()
                call(i)
                times[name].append(time.perf_counter() - start)
                cpu[name].append(time.thread_time() - start_cpu)
    stats = {}
    for name, values in times.items():
        ms, cpu_ms = np.asarray(values) * 1e3, np.asarray(cpu[name]) * 1e3
        stats[name] = {"calls": int(ms.size), "p50_ms": float(np.percentile(ms, 50)),
                       "p99_ms": float(np.percentile(ms, 99)), "mean_ms": float(ms.mean()),
                       "max_ms": float(ms.max()), "cpu_p50_ms": float(np.percentile(cpu_ms, 50)),
                       "cpu_p99_ms": float(np.percentile(cpu_ms, 99))}  # fmt: skip
    return stats
