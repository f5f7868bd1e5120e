"""The networks, with exactly the ONNX interface the daemon's manifest check expects.

- GCN (paper II-C): two graph convolutions over the normalised adjacency,
  features -> hidden -> 128, the worker (node 0) embedding, and a linear head to 4
  logits; features is 1024 (appearance) or 1033 (appearance ‖ floor relations).
- TemporalGRU (paper II-D): one GRU over [frames, D] rows (D = 162 ego, 290 collective),
  final hidden state -> logits for t and each of the next H ticks.
- Cnn1dGRU (the paper's 1D-CNN baseline): five 1-D convolutions over the worker node's
  1024-d feature of each frame -> 128, concatenated with the keypoints, then the same GRU.
- StationScorer (relation rows): one small network, shared by every station, scores
  each station from the history of its own relation to the worker; a set summary of
  all stations' states (mean and max, DeepSets) lets each score see the others.
- PeerSetScorer: a StationScorer that also pools the peers' own relations to each
  station (DeepSets over the peers, any number from 0 to the slots).
- FacingScorer: a StationScorer whose rows also say where the worker's body faces
  against each station.
"""
import functools

import torch
from torch import nn

from data import CLASSES, EMBEDDING, FACING, FEATURE, KEYPOINTS, PER_STATION, RELATIONS, TRACK_VALUES


class GCN(nn.Module):
    def __init__(self, features=FEATURE, hidden=256, dropout=0.2):
        super().__init__()
        self.l1 = nn.Linear(features, hidden)
        self.l2 = nn.Linear(hidden, EMBEDDING)
        self.head = nn.Linear(EMBEDDING, CLASSES)
        self.drop = nn.Dropout(dropout)

    def forward(self, x, adj):
        h = torch.relu(adj @ self.l1(self.drop(x)))
        h = torch.relu(adj @ self.l2(self.drop(h)))
        embedding = h[:, 0, :]  # the worker is node 0 of the star graph
        return embedding, self.head(embedding)


class TemporalGRU(nn.Module):
    def __init__(self, features, horizon, hidden=128, dropout=0.1):
        super().__init__()
        self.steps = horizon + 1
        self.gru = nn.GRU(features, hidden, batch_first=True)
        self.drop = nn.Dropout(dropout)
        self.head = nn.Linear(hidden, self.steps * CLASSES)

    def forward(self, x):
        _, h = self.gru(x)
        return self.head(self.drop(h[-1])).reshape(-1, self.steps, CLASSES)


class Cnn1dGRU(nn.Module):
    # Five convolutions over the 1024 values: the first with stride 4, then stride 2,
    # 1024 -> 16 positions; small channel counts keep training on 2 CPU cores in minutes.
    def __init__(self, horizon, hidden=128, channels=(4, 8, 8, 16, 16)):
        super().__init__()
        layers, c_in, length = [], 1, FEATURE
        for i, c in enumerate(channels):
            stride = 4 if i == 0 else 2
            layers += [nn.Conv1d(c_in, c, kernel_size=5, stride=stride, padding=2), nn.ReLU()]
            c_in, length = c, length // stride
        self.conv = nn.Sequential(*layers)
        self.proj = nn.Linear(c_in * length, EMBEDDING)
        self.temporal = TemporalGRU(EMBEDDING + KEYPOINTS, horizon, hidden)

    def forward(self, x):
        b, f, _ = x.shape
        feature, keypoints = x[..., :FEATURE], x[..., FEATURE:]
        z = self.conv(feature.reshape(b * f, 1, FEATURE)).reshape(b * f, -1)
        z = torch.relu(self.proj(z)).reshape(b, f, EMBEDDING)
        return self.temporal(torch.cat([z, keypoints], -1))


class StationScorer(nn.Module):
    """Reads relation rows (keypoints ‖ track values ‖ per station, in class order,
    core/src/floor/relations.rs) and gives logits [B, H+1, 4] like TemporalGRU.

    Every station goes through the same GRU and head, so a station's score depends on
    its relation to the worker, never on which class slot it sits in: what is learned
    about one station holds for all, on any floor. The GRU also reads, per station, the
    constant-velocity model's cost (how far the station lies off the line the worker
    walks, or its distance when the worker stands or it lies behind) and the time to
    reach it at the current closing speed, and shares the track values and a small
    projection of the keypoints. Mean and max over the stations' final states (a set
    summary, the same whatever the order) go into every station's head, so a station can
    win because all the others are being left behind — also one nobody has mapped.
    """

    def __init__(self, horizon, hidden=64, pose=16, dropout=0.1, extra=0):
        super().__init__()
        self.steps = horizon + 1
        self.pose = nn.Linear(KEYPOINTS, pose)
        # `extra`: per-station values a subclass adds to each step (PeerSetScorer).
        self.gru = nn.GRU(PER_STATION + 2 + TRACK_VALUES + pose + extra, hidden, batch_first=True)
        # The head's first layer over [own state ‖ set summary], as two linear maps
        # added with broadcasting (no Expand/Concat feeding a MatMul, which tract 0.23
        # fails to optimise).
        self.head_own = nn.Linear(hidden, hidden)
        self.head_set = nn.Linear(2 * hidden, hidden, bias=False)
        self.drop = nn.Dropout(dropout)
        self.out = nn.Linear(hidden, self.steps)

    def forward(self, x):
        return self.score(station_rows(*self.station_parts(x)))

    def station_parts(self, x):
        """The parts of every station's row: its relation block with the derived values
        [B, F, CLASSES, PER_STATION + 2], and what all stations share [B, F, n], the
        track values and the keypoints' projection."""
        keypoints, track = x[..., :KEYPOINTS], x[..., KEYPOINTS : KEYPOINTS + TRACK_VALUES]
        return station_values(x[..., KEYPOINTS:]), torch.cat([track, torch.relu(self.pose(keypoints))], -1)

    def score(self, rows):
        b, _, f, d = rows.shape
        _, h = self.gru(rows.reshape(b * CLASSES, f, d))
        h = h[-1].reshape(b, CLASSES, -1)
        # The max over the stations as elementwise maxima: tract 0.23 runs a ReduceMax
        # over this middle axis ten times slower than the three Max ops.
        top = functools.reduce(torch.maximum, h.unbind(1))
        summary = torch.cat([h.mean(1), top], -1)
        z = torch.relu(self.head_own(h) + self.head_set(summary)[:, None, :])
        return self.out(self.drop(z)).transpose(1, 2)


def station_rows(*parts):
    """Every station's rows [B, CLASSES, F, D] (class order): the parts side by side, each
    either per station [B, F, CLASSES, n] or shared by all stations [B, F, n]. The values
    are computed for all stations at once (one op per step instead of one per step and
    station: most of a small model's run time in tract, docs/BENCHMARKS.md) and joined
    station by station, since tract 0.23 fails to optimise a broadcast of the shared
    parts feeding a Concat that feeds a product, as the GRU's input does."""
    return torch.stack([torch.cat([p[..., k, :] if p.dim() == 4 else p for p in parts], -1) for k in range(CLASSES)], 1)


def station_values(rel):
    """Every station's relation block of a relation block `rel` [..., RELATIONS] with the
    two values derived from it, [..., CLASSES, PER_STATION + 2]: the constant-velocity
    model's cost (off the worker's line, or the distance when the worker stands or the
    station lies behind) and the time to reach it at the closing speed (/ 3 s, at most 1)."""
    st = rel[..., TRACK_VALUES : TRACK_VALUES + CLASSES * PER_STATION].unflatten(-1, (CLASSES, PER_STATION))
    known, dist, closing, cos, sin = st[..., 0:1], st[..., 1:2], st[..., 2:3], st[..., 4:5], st[..., 5:6]
    off_line = known * torch.where(cos > 0, dist * sin.abs(), dist)
    eta = torch.where(closing > 0.1, dist * 10 / closing.clamp(min=0.1), torch.full_like(dist, 30.0)) / 30
    return torch.cat([st, off_line, known * eta.clamp(max=1.0)], -1)


class PeerSetScorer(StationScorer):
    """A StationScorer whose collective input also holds one relation block per peer
    heard ([B, F, P, RELATIONS], core/src/floor/relations.rs `peer_set`: that peer's
    own estimate of the worker against the team map, empty slots zero). Per station,
    each peer's relation to it and its track values (presence, speed, position sigma:
    its view quality) go through one small network phi; their masked mean and max over
    the peers and the peer count / P join that station's row (DeepSets: the output is
    the same whatever the peers' order, and any number of them from 0 to P fits).
    """

    def __init__(self, horizon, slots, phi=32, **kw):
        super().__init__(horizon, extra=2 * phi + 1, **kw)
        self.slots = slots
        self.phi = nn.Sequential(nn.Linear(TRACK_VALUES + PER_STATION + 2, phi), nn.ReLU(), nn.Linear(phi, phi), nn.ReLU())

    def forward(self, x, peers):
        present = peers[..., 0:1, None]  # [B, F, P, 1, 1]: a peer's block starts with 1
        count = present.sum(2)[..., 0, :]  # [B, F, 1]
        # phi's first layer over [track values ‖ station values] as two products added
        # with broadcasting, not over a Concat of broadcast values, which tract 0.23
        # fails to optimise (as the head's first layer above).
        first, w = self.phi[0], self.phi[0].weight
        track = peers[..., None, :TRACK_VALUES] @ w[:, :TRACK_VALUES].T
        h = self.phi[1:](track + station_values(peers) @ w[:, TRACK_VALUES:].T + first.bias) * present
        mean = h.sum(2) / count[..., None].clamp(min=1)  # [B, F, CLASSES, phi]
        top = h.max(2).values  # phi's output is >= 0, so the empty slots' zeros never win
        return self.score(station_rows(*self.station_parts(x), mean, top, count / self.slots))


class FacingScorer(StationScorer):
    """A StationScorer over rows that end with the facing block (core/src/floor/
    relations.rs `facing`: [known], then per station [cos, sin] of its bearing relative
    to where the worker's body faces). Each station's row gains its own two values and
    the known flag, so the rule learned holds for every station alike."""

    def __init__(self, horizon, **kw):
        super().__init__(horizon, extra=3, **kw)

    def forward(self, x):
        face = x[..., KEYPOINTS + RELATIONS : KEYPOINTS + RELATIONS + FACING]
        known, bearings = face[..., 0:1], face[..., 1:].unflatten(-1, (CLASSES, 2))
        return self.score(station_rows(*self.station_parts(x[..., : KEYPOINTS + RELATIONS]), known, bearings))
