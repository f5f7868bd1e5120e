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
Runs in the training venv (models/train.sh). A file this script wrote can be read again
except a peer-set collective GRU, whose phi layer nets.py now exports in two parts.
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
KINDS = ("ego_gru", "collective_gru")


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
            if node not in nodes:
                sys.exit(
                    f"{path}: no MatMul node {node} holds {name}'s weights (nets.py may compute that "
                    "layer in parts, as PeerSetScorer's phi; re-export from the file training wrote)"
                )
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


def scorer_for(manifest, path):
    """The nets.py module of the GRU file `path`: a peer-set scorer if it takes the peers'
    input ([1, F, P, RELATIONS]), else as the set's rows say."""
    horizon, inputs = manifest["horizon"], onnx.load(path).graph.input
    if len(inputs) > 1:
        return PeerSetScorer(horizon, slots=inputs[1].type.tensor_type.shape.dim[2].dim_value)
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
    for kind in KINDS:
        path = os.path.join(set_dir, f"{kind}.onnx")
        module = load_weights(scorer_for(manifest, path), path)
        old = ort.InferenceSession(path, providers=["CPUExecutionProvider"])
        names = [i.name for i in old.get_inputs()]
        feeds = list(feeds_of(references[kind], rng))
        inputs = lambda feed: tuple(torch.from_numpy(feed[n]) for n in names)  # noqa: E731
        with torch.no_grad():
            for feed in feeds:
                if (d := worst([module(*inputs(feed)).numpy()], old.run(None, feed))) > TOLERANCE:
                    sys.exit(f"{path}: the weights read back give other outputs (by {d}); nothing written")
        with tempfile.TemporaryDirectory() as tmp:
            new_path = os.path.join(tmp, f"{kind}.onnx")
            export(module, inputs(feeds[0]), names, ["logits"], new_path)
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
