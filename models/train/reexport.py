"""Re-exports the station-scorer GRUs of shipped model sets under the current nets.py,
from the weights in their own ONNX files: for a change to how a network is written
that leaves what it computes alone (no training, no new data).

    models/train/reexport.py models/default models/relations ...

For each set whose rows are relation rows (`row` relations or relations_facing in its
manifest), each GRU file is read back into the matching nets.py module; PyTorch must
reproduce the file's outputs on its reference inputs (reference.json) and on random
rows to TOLERANCE, or nothing is written. The new export must match the old file the
same way in onnxruntime; then it replaces the file. reference.json and the manifest
stay as they are: the golden tests replay the old vectors through the new graphs.
Runs in the training venv (models/train.sh).
"""
import json
import os
import shutil
import sys
import tempfile

import numpy as np
import onnx
import onnxruntime as ort
import torch
from onnx import numpy_helper

from export import export
from nets import FacingScorer, PeerSetScorer, StationScorer

TOLERANCE = 1e-5
FILES = {"ego_gru": "ego_gru.onnx", "collective_gru": "collective_gru.onnx"}


def onnx_to_torch_gates(w):
    """ONNX orders a GRU's gates z, r, h along the first axis; PyTorch r, z, n."""
    z, r, h = np.split(w, 3)
    return np.concatenate([r, z, h])


def load_weights(module, path):
    """Sets every Linear and the GRU of `module` from the ONNX file PyTorch exported it
    to: a Linear `a.b` is the MatMul node `/a/a.b/MatMul` (weight transposed) plus the
    initializer `a.b.bias`; the GRU is the one GRU node."""
    m = onnx.load(path)
    init = {i.name: numpy_helper.to_array(i) for i in m.graph.initializer}
    nodes = {n.name: n for n in m.graph.node}
    state = {}
    for name, sub in module.named_modules():
        if isinstance(sub, torch.nn.Linear):
            parts = name.split(".")
            node = "/" + "/".join(".".join(parts[: i + 1]) for i in range(len(parts))) + "/MatMul"
            state[f"{name}.weight"] = init[nodes[node].input[1]].T
            if sub.bias is not None:
                state[f"{name}.bias"] = init[f"{name}.bias"]
    (gru,) = [n for n in m.graph.node if n.op_type == "GRU"]
    w, r, b = (init[i][0] for i in gru.input[1:4])
    hidden = r.shape[1]
    state |= {
        "gru.weight_ih_l0": onnx_to_torch_gates(w),
        "gru.weight_hh_l0": onnx_to_torch_gates(r),
        "gru.bias_ih_l0": onnx_to_torch_gates(b[: 3 * hidden]),
        "gru.bias_hh_l0": onnx_to_torch_gates(b[3 * hidden :]),
    }
    module.load_state_dict({k: torch.from_numpy(np.array(v, np.float32)) for k, v in state.items()}, strict=True)
    return module.eval()


def scorer_for(manifest, kind, path):
    horizon = manifest["horizon"]
    inputs = {i.name for i in onnx.load(path).graph.input}
    if "peers" in inputs:
        slots = onnx.load(path).graph.input[1].type.tensor_type.shape.dim[2].dim_value
        return PeerSetScorer(horizon, slots=slots)
    return FacingScorer(horizon) if manifest["row"] == "relations_facing" else StationScorer(horizon)


def feeds_of(reference, rng):
    """The reference inputs, then random ones of the same shapes (values in [-1, 3]: every
    branch of the derived values taken, known or not, closing or not)."""
    yield {n: np.array(v["data"], np.float32).reshape(v["shape"]) for n, v in reference["inputs"].items()}
    for _ in range(8):
        yield {n: rng.uniform(-1, 3, v["shape"]).astype(np.float32) for n, v in reference["inputs"].items()}


def worst(a, b):
    return max(float(np.abs(x - y).max()) for x, y in zip(a, b))


def reexport(set_dir):
    manifest = json.load(open(os.path.join(set_dir, "manifest.json")))
    if manifest.get("row") not in ("relations", "relations_facing"):
        print(f"{set_dir}: row {manifest.get('row')!r}, not a station scorer: left alone")
        return
    references = json.load(open(os.path.join(set_dir, "reference.json")))
    rng = np.random.default_rng(7)
    for kind, file in FILES.items():
        path = os.path.join(set_dir, file)
        module = load_weights(scorer_for(manifest, kind, path), path)
        old = ort.InferenceSession(path, providers=["CPUExecutionProvider"])
        feeds = list(feeds_of(references[kind], rng))
        with torch.no_grad():
            for feed in feeds:
                got = module(*(torch.from_numpy(feed[i.name]) for i in old.get_inputs()))
                if (d := worst([got.numpy()], old.run(None, feed))) > TOLERANCE:
                    sys.exit(f"{path}: the weights read back give other outputs (by {d}); nothing written")
        with tempfile.TemporaryDirectory() as tmp:
            new_path = os.path.join(tmp, file)
            names = [i.name for i in old.get_inputs()]
            x = tuple(torch.from_numpy(feeds[0][n]) for n in names)
            export(module, x, names, ["logits"], new_path)
            new = ort.InferenceSession(new_path, providers=["CPUExecutionProvider"])
            d = max(worst(new.run(None, f), old.run(None, f)) for f in feeds)
            if d > TOLERANCE:
                sys.exit(f"{path}: the new export differs from the old file by {d}; nothing written")
            before, after = (len(onnx.load(p).graph.node) for p in (path, new_path))
            shutil.copyfile(new_path, path)
        print(f"{path}: {before} -> {after} nodes, outputs within {d:.1e}")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    for d in sys.argv[1:]:
        reexport(d)
