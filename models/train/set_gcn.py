"""Puts a trained GCN into shipped model sets whose GRUs do not read its embedding:
what train.sh would write for them with that GCN, without training their GRUs again.

    models/train/set_gcn.py GCN_DIR models/default models/relations ...

GCN_DIR is what train_gcn.py writes (gcn.onnx, gcn_reference.json, gcn.json). A set
qualifies when its rows are relation rows (`row` in its manifest): those rows hold the
keypoints and the floor relations, never the embedding, so its GRUs were trained on
the same values whatever GCN ran beside them (the temporal export goes through the
paper's GCN either way, models/train.sh). Sets with the paper's rows are refused. Each
set's gcn.onnx is replaced (its node count fixed again if the set's was fixed,
node_dim.py), and its manifest and reference.json get what train_temporal.py writes
for a GCN: the graph it reads (max_nodes, edge_weight, node_features), its interface,
its training report and test accuracy, its reference vectors.
Runs in the training venv.
"""
import json
import os
import sys

import onnx

from export import io_spec
from node_dim import set_node_dim

GRAPH_KEYS = ("max_nodes", "edge_weight", "node_features")


def graph_of(gcn_report, fallback):
    """The graph a GCN reads: its report's, else `fallback`'s (an export's description,
    a manifest), node_features absent meaning the paper's."""
    return {k: gcn_report.get(k, fallback.get(k, "appearance")) for k in GRAPH_KEYS}


def gcn_test_accuracy(gcn_report):
    """A GCN's test accuracy per scenario on its own test graphs, as a manifest's
    evaluation holds it."""
    return {f"scenario_{s}": {"t": t, "on": "the GCN's test graphs"} for s, t in gcn_report["test_accuracy_by_scenario"].items()}


def manifest_graph(manifest, graph):
    """Writes the graph keys into a manifest (node_features only when not the paper's)."""
    manifest["max_nodes"] = graph["max_nodes"]
    manifest["edge_weight"] = graph["edge_weight"]
    manifest.pop("node_features", None)
    if graph["node_features"] != "appearance":
        manifest["node_features"] = graph["node_features"]


def put(gcn_dir, set_dir):
    with open(os.path.join(set_dir, "manifest.json")) as f:
        manifest = json.load(f)
    if "row" not in manifest:
        raise SystemExit(f"{set_dir}: its GRUs read the GCN's embedding (the paper's rows); train it again instead")
    with open(os.path.join(gcn_dir, "gcn.json")) as f:
        report = json.load(f)
    with open(os.path.join(gcn_dir, "gcn_reference.json")) as f:
        gcn_reference = json.load(f)
    if set(GRAPH_KEYS) - set(report):
        raise SystemExit(f"{gcn_dir}/gcn.json does not say which graphs the GCN reads ({', '.join(GRAPH_KEYS)})")
    graph = graph_of(report, {})

    old_nodes = manifest["models"]["gcn"]["inputs"][0]["shape"][1]
    model = onnx.load(os.path.join(gcn_dir, "gcn.onnx"))
    if isinstance(old_nodes, int):
        set_node_dim(model, old_nodes)
    path = os.path.join(set_dir, "gcn.onnx")
    onnx.save(model, path)

    manifest_graph(manifest, graph)
    manifest["models"]["gcn"] = {"file": "gcn.onnx", **io_spec(path)}
    manifest["training"]["gcn"] = report
    manifest["evaluation"]["accuracy"]["gcn"] = gcn_test_accuracy(report)
    with open(os.path.join(set_dir, "manifest.json"), "w") as f:
        json.dump(manifest, f, indent=2)
        f.write("\n")
    with open(os.path.join(set_dir, "reference.json")) as f:
        references = json.load(f)
    references["gcn"] = gcn_reference
    with open(os.path.join(set_dir, "reference.json"), "w") as f:
        json.dump(references, f, separators=(",", ":"))
    print(f"{set_dir}: GCN of {gcn_dir} ({graph['node_features']} graphs, node count {old_nodes})")


def main():
    if len(sys.argv) < 3:
        raise SystemExit(__doc__)
    for set_dir in sys.argv[2:]:
        put(sys.argv[1], set_dir)


if __name__ == "__main__":
    main()
