#!/usr/bin/env python3
"""Stage 2: trains the ego-GRU, the collective-GRU (and the 1D-CNN baseline), calibrates
them, exports them and writes a complete model set the daemon loads.

Usage: train_temporal.py --data DIR [DIR ...] --gcn-dir DIR --out models/NAME
                         [--window 20 --horizon 20 --frames W] [--cnn1d] [--relations [--peer-set | --facing]] [--epochs 8]

DIR are `spwi-sim dataset --gcn GCN_DIR/gcn.onnx` exports (so the embeddings are the
ones the agent's Rust code computes). Writes OUT/{gcn,ego_gru,collective_gru[,cnn1d]}.onnx,
OUT/manifest.json (interface, W, H, frames, temperatures, dataset, test accuracies,
calibration errors) and OUT/reference.json (golden vectors for the Rust tests).
"""
import argparse
import json
import os
import shutil
import subprocess
import time

import numpy as np
import torch
from torch import nn

from data import CLASSES, EMBEDDING, FEATURE, KEYPOINTS, PER_STATION, RELATIONS, TRACK_VALUES, Export, Sequences, batch
from export import OPSET, export, io_spec
from nets import Cnn1dGRU, FacingScorer, PeerSetScorer, StationScorer, TemporalGRU
from set_gcn import gcn_test_accuracy, graph_of, manifest_graph

DIMS = {"ego": EMBEDDING + KEYPOINTS, "collective": 2 * EMBEDDING + KEYPOINTS, "cnn1d": FEATURE + KEYPOINTS}
FILES = {"ego": "ego_gru", "collective": "collective_gru", "cnn1d": "cnn1d"}


def logits_for(model, seqs, ends, a, kind, chunk=2048):
    """Logits [N, H+1, 4] and labels [N, H+1] over the given window ends (no peer dropout)."""
    model.eval()
    out, labels = [], []
    with torch.no_grad():
        for i in range(0, len(ends[0]), chunk):
            e, t, r = (x[i : i + chunk] for x in ends)
            x, y = batch(seqs, e, t, r, a.window, a.frames, a.horizon, kind, relations=a.relations, peer_set=a.peer_set, facing=a.facing)
            out.append(model(*x))
            labels.append(y)
    if not out:
        return torch.zeros(0, a.horizon + 1, CLASSES), torch.zeros(0, a.horizon + 1, dtype=torch.long)
    return torch.cat(out), torch.cat(labels)


def accuracies(logits, labels):
    hit = (logits.argmax(-1) == labels).float()
    return {"t": round(float(hit[:, 0].mean()), 4), "future": round(float(hit[:, 1:].mean()), 4) if hit.shape[1] > 1 else None}


def fit_temperature(logits, labels):
    """Temperature scaling (Guo et al. 2017) over every step, on the validation split."""
    log_t = torch.zeros(1, requires_grad=True)
    opt = torch.optim.LBFGS([log_t], lr=0.1, max_iter=200)
    flat, y = logits.reshape(-1, CLASSES), labels.reshape(-1)

    def closure():
        opt.zero_grad()
        loss = nn.functional.cross_entropy(flat / log_t.exp(), y)
        loss.backward()
        return loss

    opt.step(closure)
    return float(log_t.detach().exp())


def ece(logits, labels, temperature=1.0, bins=15):
    """Expected calibration error of the prediction at t."""
    p = torch.softmax(logits[:, 0] / temperature, -1)
    conf, pred = p.max(-1)
    correct = (pred == labels[:, 0]).float()
    edges = torch.linspace(0, 1, bins + 1)
    total = 0.0
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = (conf > lo) & (conf <= hi)
        if m.any():
            total += float(m.float().mean() * (conf[m].mean() - correct[m].mean()).abs())
    return round(total, 4)


def train(kind, all_seqs, a, rng):
    if kind == "cnn1d":
        model = Cnn1dGRU(a.horizon)
    elif a.relations and a.peer_set and kind == "collective":
        model = PeerSetScorer(a.horizon, slots=all_seqs[0].rel_peers.shape[-2])
    elif a.relations and a.facing:
        model = FacingScorer(a.horizon)
    elif a.relations:
        model = StationScorer(a.horizon)
    else:
        model = TemporalGRU(DIMS[kind], a.horizon)
    opt = torch.optim.AdamW(model.parameters(), lr=2e-3, weight_decay=1e-4)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, a.epochs)
    train_ends = [s.ends("train", every=a.every, tracked=a.relations and kind != "cnn1d") for s in all_seqs]
    val_ends = [s.ends("validation", every=a.every * 2) for s in all_seqs]
    sizes = np.array([len(e[0]) for e in train_ends], dtype=np.float64)
    best, best_state = -1.0, None
    batch_size = 256
    for epoch in range(a.epochs):
        model.train()
        started = time.time()
        steps = (a.samples // 2 if kind == "cnn1d" else a.samples) // batch_size
        # each batch from one export, chosen in proportion to its size
        which = rng.choice(len(all_seqs), size=steps, p=sizes / sizes.sum())
        for k in which:
            s, (e, t, r) = all_seqs[k], train_ends[k]
            i = torch.from_numpy(rng.integers(0, len(e), batch_size))
            peer_rng = rng if kind == "collective" else None
            x, y = batch(
                s, e[i], t[i], r[i], a.window, a.frames, a.horizon, kind, peer_rng=peer_rng, relations=a.relations, peer_set=a.peer_set, facing=a.facing
            )
            loss = nn.functional.cross_entropy(model(*x).reshape(-1, CLASSES), y.reshape(-1))
            opt.zero_grad()
            loss.backward()
            nn.utils.clip_grad_norm_(model.parameters(), 1.0)
            opt.step()
        sched.step()
        val = [logits_for(model, s, v, a, kind) for s, v in zip(all_seqs, val_ends)]
        acc = accuracies(torch.cat([v[0] for v in val]), torch.cat([v[1] for v in val]))
        score = acc["t"] + (acc["future"] or 0)
        if score > best:
            best, best_state = score, {k: v.clone() for k, v in model.state_dict().items()}
        print(
            f"  {kind} epoch {epoch + 1}/{a.epochs}: loss {loss.item():.3f}, validation t {acc['t']:.3f} "
            f"future {acc['future']}, {time.time() - started:.0f} s",
            flush=True,
        )
    model.load_state_dict(best_state)
    model.eval()
    return model, val_ends


def reference_window(s, a, kind):
    """The golden test's input: the first test window of export `s` that shows what
    the model reads — for relation rows two or more stations mapped on its last row,
    with facing the worker's facing known on it, and for a peer set two or more peers
    heard on it (an episode's first windows have empty maps and would leave those
    parts of the model untested)."""
    e, t, r = s.ends("test")
    for i in range(0, len(e), 512):
        x, _ = batch(s, e[i : i + 512], t[i : i + 512], r[i : i + 512], a.window, a.frames, a.horizon, kind, relations=a.relations, peer_set=a.peer_set, facing=a.facing)
        ok = torch.ones(len(x[0]), dtype=torch.bool)
        if a.relations and kind != "cnn1d":
            known = x[0][:, -1, KEYPOINTS + TRACK_VALUES :: PER_STATION][:, :CLASSES]
            ok &= (known > 0).sum(1) >= 2
        if len(x) > 1:
            ok &= (x[1][:, -1, :, 0] > 0).sum(1) >= 2
        if a.facing and kind != "cnn1d":  # and where the worker faces
            ok &= x[0][:, -1, KEYPOINTS + RELATIONS] > 0
        if ok.any():
            j = int(ok.nonzero()[0])
            return tuple(v[j : j + 1] for v in x)
    x, _ = batch(s, e[:1], t[:1], r[:1], a.window, a.frames, a.horizon, kind, relations=a.relations, peer_set=a.peer_set, facing=a.facing)
    return x


def code_version():
    try:
        return subprocess.run(["git", "describe", "--always", "--dirty"], capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", nargs="+", required=True)
    ap.add_argument("--gcn-dir", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--window", type=int, default=20)
    ap.add_argument("--horizon", type=int, default=20)
    ap.add_argument("--frames", type=int)
    ap.add_argument("--cnn1d", action="store_true", help="also train the 1D-CNN baseline")
    ap.add_argument("--relations", action="store_true", help="rows end with the worker's relations to the mapped stations")
    ap.add_argument(
        "--peer-set", action="store_true", help="with --relations: the collective GRU pools one relation block per peer it heard (PeerSetScorer)"
    )
    ap.add_argument(
        "--facing", action="store_true", help="with --relations: rows end with where the worker faces against each station (FacingScorer)"
    )
    ap.add_argument("--epochs", type=int, default=10)
    ap.add_argument("--samples", type=int, default=60000, help="training windows per epoch")
    ap.add_argument("--every", type=int, default=2, help="use windows ending every Nth tick")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()
    a.frames = a.frames or a.window
    if (a.peer_set or a.facing) and not a.relations or (a.peer_set and a.facing):
        ap.error("--peer-set and --facing each need --relations, and not each other")
    torch.manual_seed(a.seed)
    torch.set_num_threads(a.threads)
    rng = np.random.default_rng(a.seed)
    started = time.time()
    exports = [Export(p) for p in a.data]
    all_seqs = [Sequences(ex, need_features=a.cnn1d) for ex in exports]
    name = os.path.basename(os.path.normpath(a.out))
    print(f"{name}: W {a.window}, frames {a.frames}, H {a.horizon}, scenarios {[s.scenario for s in all_seqs]}", flush=True)

    os.makedirs(a.out, exist_ok=True)
    shutil.copyfile(os.path.join(a.gcn_dir, "gcn.onnx"), os.path.join(a.out, "gcn.onnx"))
    with open(os.path.join(a.gcn_dir, "gcn_reference.json")) as f:
        references = {"gcn": json.load(f)}
    with open(os.path.join(a.gcn_dir, "gcn.json")) as f:
        gcn_report = json.load(f)

    # The graphs this set's GCN reads: its own report's (a GCN trained on other graphs
    # than the export's, e.g. floor relations beside the paper's), else the export's.
    graph = graph_of(gcn_report, exports[0].desc)
    evaluation = {"gcn": {}, "ego": {}, "collective": {}}
    if graph != graph_of({}, exports[0].desc):
        # The export ran another GCN: this one's accuracy on its own test graphs.
        evaluation["gcn"] = gcn_test_accuracy(gcn_report)
    else:
        for s in all_seqs:  # the GCN alone, on the same test windows the GRUs are scored on
            e, t, r = s.ends("test")
            hit = (s.gcn_logits[e, t, r].argmax(-1) == s.truth[e, t, r, 0]).float()
            evaluation["gcn"][f"scenario_{s.scenario}"] = {"t": round(float(hit.mean()), 4)}
    models, calibration = {}, {}
    kinds = ["ego", "collective"] + (["cnn1d"] if a.cnn1d else [])
    for kind in kinds:
        model, val_ends = train(kind, all_seqs, a, rng)
        vl = [logits_for(model, s, v, a, kind) for s, v in zip(all_seqs, val_ends)]
        temperature = fit_temperature(torch.cat([v[0] for v in vl]), torch.cat([v[1] for v in vl]))
        evaluation[kind] = {}
        test_logits, test_labels = [], []
        for s in all_seqs:
            lg, lb = logits_for(model, s, s.ends("test"), a, kind)
            evaluation[kind][f"scenario_{s.scenario}"] = accuracies(lg, lb)
            test_logits.append(lg)
            test_labels.append(lb)
        lg, lb = torch.cat(test_logits), torch.cat(test_labels)
        calibration[kind] = {"temperature": round(temperature, 4), "ece_test_before": ece(lg, lb), "ece_test_after": ece(lg, lb, temperature)}
        x = reference_window(all_seqs[-1], a, kind)
        path = os.path.join(a.out, f"{FILES[kind]}.onnx")
        references[FILES[kind]] = export(model, x, ["x", "peers"][: len(x)], ["logits"], path)
        models[FILES[kind]] = {"file": f"{FILES[kind]}.onnx", **io_spec(path), "temperature": round(temperature, 4)}
        print(f"  {kind}: test {evaluation[kind]}, calibration {calibration[kind]}", flush=True)

    manifest = {
        "name": name,
        "classes": ["storage", "workstation", "assembly", "manufacturing"],
        "max_nodes": graph["max_nodes"],
        "window": a.window,
        **({"frames": a.frames} if a.frames != a.window else {}),
        "horizon": a.horizon,
        "edge_weight": graph["edge_weight"],
        **({"row": "relations_facing" if a.facing else "relations"} if a.relations else {}),
        **({"peer_slots": int(all_seqs[0].rel_peers.shape[-2])} if a.peer_set else {}),
        "consensus": {"alpha": 0.5, "beta": 0.5},
        "opset": OPSET,
        "dataset": {
            "exports": [
                {
                    **{k: ex.desc.get(k) for k in ("scenario", "episodes", "robots", "ticks_per_episode", "seed", "layouts")},
                    # the cameras and warm-ups the episodes ran under (sim/src/training_mix.rs)
                    "conditions": {k: v for k, v in ex.desc.get("conditions", {}).items() if k in ("track_share", "warm_share", "warm_up_max_s")},
                }
                for ex in exports
            ],
            "episode_seed": exports[0].desc["episode_seed"],
            "split": exports[0].desc["split"],
        },
        "training": {
            "code_version": code_version(),
            "torch": torch.__version__,
            "seed": a.seed,
            "epochs": a.epochs,
            "windows_per_epoch": a.samples,
            "gcn": gcn_report,
            "seconds": round(time.time() - started, 1),
        },
        "evaluation": {
            "split": "test",
            "note": "accuracy over the test episodes' ticks where the robot sees the worker; future = mean over t+1..t+H; collective with every other robot of the episode as a peer"
            + (" (peer set: with the peers it heard, a random 0 to all of them, 10 % of their messages lost)" if a.peer_set else ""),
            "accuracy": evaluation,
            "calibration": calibration,
        },
        "models": {"gcn": {"file": "gcn.onnx", **io_spec(os.path.join(a.out, "gcn.onnx"))}, **models},
    }
    manifest_graph(manifest, graph)
    with open(os.path.join(a.out, "manifest.json"), "w") as f:
        json.dump(manifest, f, indent=2)
        f.write("\n")
    with open(os.path.join(a.out, "reference.json"), "w") as f:
        json.dump(references, f, separators=(",", ":"))
    print(f"{name}: wrote {a.out} in {time.time() - started:.0f} s", flush=True)


if __name__ == "__main__":
    main()
