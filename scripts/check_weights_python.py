#!/usr/bin/env python3
"""Opens the deployed weight files with Python's `safetensors` package (issue 3):
both files must load with `safetensors.numpy.load_file`, hold `layers.{i}.weight`
[out, in] and `layers.{i}.bias` [out] for consecutive i with chained shapes, and
carry the metadata DESIGN §4 lists.

    python3 -m venv /tmp/st && /tmp/st/bin/pip install safetensors numpy
    /tmp/st/bin/python scripts/check_weights_python.py critic-weights/avant635

The argument is one machine's directory (default: critic-weights/avant635).
"""
import sys
from pathlib import Path

from safetensors import safe_open
from safetensors.numpy import load_file

REQUIRED_METADATA = [
    "format_version", "role", "encoder", "activation", "output_size", "dt",
    "cost.w", "cost.p", "gamma", "steps", "lambda_l", "git_commit",
    "machine.beta_max", "machine.v_max",
]
# Encoder inputs (control::encoder): 7 for the actor, 9 (with the action) for the critic.
INPUTS = {"critic": 9, "actor": 7}


def check(path: Path, role: str) -> str:
    tensors = load_file(str(path))
    with safe_open(str(path), framework="numpy") as f:
        meta = f.metadata() or {}
    missing = [k for k in REQUIRED_METADATA if k not in meta]
    if missing:
        raise SystemExit(f"{path}: metadata keys missing: {missing}")
    if meta["role"] != role:
        raise SystemExit(f"{path}: role {meta['role']!r}, expected {role!r}")
    n = len(tensors) // 2
    expected = {f"layers.{i}.{p}" for i in range(n) for p in ("weight", "bias")}
    if set(tensors) != expected:
        raise SystemExit(f"{path}: tensor names {sorted(tensors)} are not {sorted(expected)}")
    width = INPUTS[role]
    shapes = []
    for i in range(n):
        w, b = tensors[f"layers.{i}.weight"], tensors[f"layers.{i}.bias"]
        if w.ndim != 2 or w.shape[1] != width or b.shape != (w.shape[0],):
            raise SystemExit(f"{path}: layer {i} has weight {w.shape}, bias {b.shape}, input {width}")
        width = w.shape[0]
        shapes.append(tuple(w.shape))
    out = int(meta["output_size"])
    if width != out:
        raise SystemExit(f"{path}: last layer has {width} outputs, metadata says {out}")
    return f"{path}: {n} layers {shapes}, dtype {tensors['layers.0.weight'].dtype}, " \
           f"steps {meta['steps']}, cost {meta.get('cost.form', 'quasi-norm')} w=[{meta['cost.w']}]"


def main() -> None:
    root = Path(sys.argv[1] if len(sys.argv) > 1 else "critic-weights/avant635")
    for role in ("critic", "actor"):
        print(check(root / f"{role}.safetensors", role))


if __name__ == "__main__":
    main()
