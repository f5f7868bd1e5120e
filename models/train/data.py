"""Reads what `spwi-sim dataset` exports and turns it into training batches.

The export is one .npy per array plus dataset.json (see sim/src/dataset.rs). The
temporal arrays are ordered episode-major, then tick, then robot, so they reshape to
[episodes, ticks, robots, ...]. Batches are built here exactly as the daemon builds its
window (core/src/temporal.rs): the W ticks ending at t, left-padded with zeros before
the first tick, a row of zeros where a part is missing (worker not seen, no peer saw
it), and `frames` of the W rows picked at uniform intervals by the same formula.
With `relations`, a row is the keypoints and the worker's relations to the mapped
stations: the robot's own (ego) or the team's (collective), as the agent computes them.
With `peer_set` too, the collective's rows are the team's as the robot holds it when it
hears a random subset of its peers (`relations_heard`), and a second input holds one
relation block per peer it heard (`relations_peers`). With `facing`, each relation row
also ends with where the worker's body faces against each station (`facing_ego` or
`facing_team`: core/src/floor/relations.rs, `facing`).
"""
import json
import os

import numpy as np
import torch

CLASSES = 4
EMBEDDING = 128
KEYPOINTS = 34
FEATURE = 1024
# core/src/floor/relations.rs: RELATION_DIM (TRACK_VALUES + 4 stations x PER_STATION)
TRACK_VALUES = 3
PER_STATION = 6
RELATIONS = TRACK_VALUES + CLASSES * PER_STATION
# core/src/floor/relations.rs: FACING_DIM ([facing known] + 4 stations x [cos, sin])
FACING = 1 + CLASSES * 2
SPLITS = {"train": 0, "validation": 1, "test": 2}


def frame_offsets(window, frames):
    """Offsets (from the oldest tick) of the rows a model reading `frames` of a
    `window`-tick history sees: round(j (window-1) / (frames-1)), halves up."""
    assert 1 <= frames <= window
    if frames == 1:
        return [window - 1]
    return [(2 * j * (window - 1) + (frames - 1)) // (2 * (frames - 1)) for j in range(frames)]


class Export:
    """One `spwi-sim dataset` folder."""

    def __init__(self, path):
        self.path = path
        with open(os.path.join(path, "dataset.json")) as f:
            self.desc = json.load(f)
        self.scenario = self.desc["scenario"]
        self.episodes = self.desc["episodes"]
        self.ticks = self.desc["ticks_per_episode"]
        self.robots = self.desc["robots"]

    def has(self, part, name):
        return os.path.exists(os.path.join(self.path, part, f"{name}.npy"))

    def spatial(self, name):
        return np.load(os.path.join(self.path, "spatial", f"{name}.npy"), mmap_mode="r")

    def temporal(self, name):
        """[episodes, ticks, robots, ...], loaded into memory."""
        a = np.load(os.path.join(self.path, "temporal", f"{name}.npy"))
        return a.reshape(self.episodes, self.ticks, self.robots, *a.shape[1:])


class Sequences:
    """Every (episode, tick, robot) of one export as tensors, and the windows that
    end at the ticks where the robot sees the worker (the only ticks it votes)."""

    def __init__(self, ex, need_features=False):
        self.scenario = ex.scenario
        self.robots = ex.robots
        self.seen = torch.from_numpy(ex.temporal("seen").astype(np.bool_))
        self.emb = torch.from_numpy(ex.temporal("embedding"))
        self.gcn_logits = torch.from_numpy(ex.temporal("gcn_logits"))
        self.keypoints = torch.from_numpy(ex.temporal("keypoints"))
        self.truth = torch.from_numpy(ex.temporal("truth").astype(np.int64))
        self.visibility = torch.from_numpy(ex.temporal("visibility").astype(np.float32))
        self.feature = torch.from_numpy(ex.temporal("human_feature")) if need_features else None
        self.rel_ego = torch.from_numpy(ex.temporal("relations_ego"))
        self.rel_team = torch.from_numpy(ex.temporal("relations_team"))
        heard = ex.has("temporal", "relations_peers")
        self.rel_heard = torch.from_numpy(ex.temporal("relations_heard")) if heard else None
        self.rel_peers = torch.from_numpy(ex.temporal("relations_peers")) if heard else None
        facing = ex.has("temporal", "facing_team")
        self.facing_ego = torch.from_numpy(ex.temporal("facing_ego")) if facing else None
        self.facing_team = torch.from_numpy(ex.temporal("facing_team")) if facing else None
        self.split = ex.temporal("split")[:, 0, 0]
        self.seed = ex.desc["seed"]

    def ends(self, split, every=1, rng=None, tracked=False):
        """(episode, tick, robot) index tensors of the windows to use in `split`: the
        ticks the robot sees the worker, and with `tracked` also those on which its own
        track of the worker is fresh (a relation set votes on those too)."""
        episodes = np.flatnonzero(self.split == SPLITS[split])
        seen = self.seen[episodes].numpy()
        if tracked:
            seen = seen | (self.rel_ego[episodes, ..., 0].numpy() > 0)
        e, t, r = np.nonzero(seen)
        keep = (t % every) == (rng.integers(every) if rng is not None else 0)
        return (torch.from_numpy(episodes[e[keep]]), torch.from_numpy(t[keep]), torch.from_numpy(r[keep]))


def gather(seqs, e, t, r, window, frames):
    """Tick indices [B, F] of each window, clipped, and which are real (not padding)."""
    off = torch.tensor(frame_offsets(window, frames))
    tt = t[:, None] - (window - 1) + off[None, :]
    valid = tt >= 0
    return tt.clamp(min=0), valid


def batch(seqs, e, t, r, window, frames, horizon, kind, peer_rng=None, peer_drop=0.1, relations=False, peer_set=False, facing=False):
    """The model's inputs (a tuple: rows [B, F, D], and for a peer set the peer blocks
    [B, F, P, RELATIONS]) and labels [B, H+1] for `kind` in ego, collective, cnn1d
    (with `relations`, ego and collective rows end with the relation block, and with
    `facing` then the facing block).

    Collective peers (their shares of the tick before): at evaluation (peer_rng None)
    every other robot of the episode;
    in training a random subset of 0..R-1 of them (0 with a small probability, so the
    model also works alone), each missing on a tick with probability `peer_drop`.
    """
    tt, valid = gather(seqs, e, t, r, window, frames)
    E, R = e[:, None], r[:, None]
    v = valid[..., None].float()
    kp = seqs.keypoints[E, tt, R] * v
    labels = seqs.truth[e, t, r, : horizon + 1]
    if relations and kind == "collective" and peer_set:  # the peers this robot heard
        if seqs.rel_peers is None:
            raise SystemExit("a peer-set model needs an export with relations_peers (spwi-sim dataset, 2026-12-02 on)")
        return (torch.cat([kp, seqs.rel_heard[E, tt, R] * v], -1), seqs.rel_peers[E, tt, R] * v[..., None]), labels
    if relations and kind != "cnn1d":  # core/src/temporal.rs, RowLayout::Relations: keypoints ‖ relations
        rel = seqs.rel_ego if kind == "ego" else seqs.rel_team
        parts = [kp, rel[E, tt, R] * v]
        if facing:  # RowLayout::RelationsFacing: ‖ facing
            if seqs.facing_team is None:
                raise SystemExit("a facing model needs an export with facing_ego and facing_team (spwi-sim dataset, 2026-12-02 on)")
            parts.append((seqs.facing_ego if kind == "ego" else seqs.facing_team)[E, tt, R] * v)
        return (torch.cat(parts, -1),), labels
    if kind == "ego":
        return (torch.cat([seqs.emb[E, tt, R] * v, kp], -1),), labels
    if kind == "cnn1d":
        return (torch.cat([seqs.feature[E, tt, R] * v, kp], -1),), labels
    assert kind == "collective"
    # Each peer's share of the tick before, as the daemon holds it when it votes on its
    # own frame (core/src/engine/step.rs, `vote`); nothing before the first tick.
    before, had = (tt - 1).clamp(min=0), (tt > 0)[..., None].float()
    all_emb = seqs.emb[E, before]  # [B, F, R, 128]
    present = seqs.seen[E, before].float() * v * had  # [B, F, R]
    others = torch.ones(len(e), seqs.robots)
    others[torch.arange(len(e)), r] = 0
    if peer_rng is not None:
        # choose how many peers each sample keeps (0 rarely), then which
        k = torch.from_numpy(peer_rng.integers(1, seqs.robots, len(e)))
        k[torch.from_numpy(peer_rng.random(len(e)) < 0.05)] = 0
        order = torch.from_numpy(peer_rng.random((len(e), seqs.robots))).float() + (1 - others) * 2
        rank = order.argsort(1).argsort(1)
        others = others * (rank < k[:, None]).float()
        drop = torch.from_numpy(peer_rng.random(present.shape) < peer_drop).float()
        present = present * (1 - drop)
    w = present * others[:, None, :]
    mean = (w[..., None] * all_emb).sum(2) / w.sum(2, keepdim=True).clamp(min=1)
    return (torch.cat([seqs.emb[E, tt, R] * v, mean, kp], -1),), labels
