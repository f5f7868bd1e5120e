#!/usr/bin/env python3
"""Names the GCN's node dimension ("nodes") instead of fixing it at max_nodes, or
fixes it again.

A GCN whose inputs are x [1, nodes, 1024] and adj [1, nodes, nodes] is fed only the
graph's real nodes (the worker and the objects seen, usually 2 to 5) instead of all
max_nodes padded ones: the two layers' products shrink with it, and the worker node's
output is the same (padding rows have no edge to it). Nothing else in the graph may
depend on the node count; the daemon refuses a node dimension named in some inputs and
fixed in others.

export.py applies it to every GCN it exports. Run on existing files (onnx only):
    python3 models/train/node_dim.py models/default/gcn.onnx ...
The daemon also runs a GCN that fixes the count (it then pads every graph to it), as
a model from elsewhere may; the study sets ship that way so that the golden tests cover
both. `--fixed N SET_DIR ...` fixes it at N in a set's gcn.onnx and its manifest:
    python3 models/train/node_dim.py --fixed 16 models/w10-h10
"""
import json
import os
import sys

import onnx

NAME = "nodes"
AXES = {"x": (1,), "adj": (1, 2)}


def set_node_dim(model, size=None):
    """Names (size None) or fixes at `size` dimension 1 of x and dimensions 1 and 2 of
    adj, in place."""
    for i in model.graph.input:
        for axis in AXES.get(i.name, ()):
            dim = i.type.tensor_type.shape.dim[axis]
            dim.Clear()
            if size is None:
                dim.dim_param = NAME
            else:
                dim.dim_value = size
    missing = set(AXES) - {i.name for i in model.graph.input}
    if missing:
        raise SystemExit(f"not a GCN: no input named {sorted(missing)}")
    del model.graph.value_info[:]  # shapes inferred for another size no longer hold
    onnx.checker.check_model(model, full_check=True)


def fix_set(set_dir, size):
    """Fixes the node count of the GCN of the model set in `set_dir` (file and manifest)."""
    path = os.path.join(set_dir, "gcn.onnx")
    m = onnx.load(path)
    set_node_dim(m, size)
    onnx.save(m, path)
    manifest_path = os.path.join(set_dir, "manifest.json")
    with open(manifest_path) as f:
        manifest = json.load(f)
    for i in manifest["models"]["gcn"]["inputs"]:
        for axis in AXES[i["name"]]:
            i["shape"][axis] = size
    with open(manifest_path, "w") as f:
        json.dump(manifest, f, indent=2)
        f.write("\n")
    print(f"{set_dir}: GCN node count fixed at {size}")


def main():
    args = sys.argv[1:]
    if args[:1] == ["--fixed"]:
        size = int(args[1])
        for set_dir in args[2:]:
            fix_set(set_dir, size)
        return
    for path in args:
        m = onnx.load(path)
        set_node_dim(m)
        onnx.save(m, path)
        print(f"{path}: node dimension named {NAME!r}")


if __name__ == "__main__":
    main()
