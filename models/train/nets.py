"""The networks, with exactly the ONNX interface the daemon's manifest check expects.

- GCN (paper II-C): two graph convolutions over the normalised adjacency,
  1024 -> hidden -> 128, the worker (node 0) embedding, and a linear head to 4 logits.
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
import torch
from torch import nn

from data import CLASSES, EMBEDDING, FACING, FEATURE, KEYPOINTS, PER_STATION, RELATIONS, TRACK_VALUES


class GCN(nn.Module):
    def __init__(self, hidden=256, dropout=0.2):
        super().__init__()
        self.l1 = nn.Linear(FEATURE, hidden)
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
    agent/src/floor/relations.rs) and gives logits [B, H+1, 4] like TemporalGRU.

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
        return self.score(self.station_rows(x))

    def station_rows(self, x):
        """Per station (class order), its [B, F, D] rows: its relation block, the
        derived values, the track values and the keypoints' projection."""
        keypoints, track = x[..., :KEYPOINTS], x[..., KEYPOINTS : KEYPOINTS + TRACK_VALUES]
        shared = torch.cat([track, torch.relu(self.pose(keypoints))], -1)
        return [torch.cat([station_values(x[..., KEYPOINTS:], k), shared], -1) for k in range(CLASSES)]

    def score(self, stations):
        b, f, _ = stations[0].shape
        rows = torch.stack(stations, 1).reshape(b * CLASSES, f, -1)  # station-major
        _, h = self.gru(rows)
        h = h[-1].reshape(b, CLASSES, -1)
        summary = torch.cat([h.mean(1), h.max(1).values], -1)
        z = torch.relu(self.head_own(h) + self.head_set(summary)[:, None, :])
        return self.out(self.drop(z)).transpose(1, 2)


def station_values(rel, k):
    """Station k's relation block of a relation block `rel` [..., RELATIONS] and the two
    values derived from it: the constant-velocity model's cost (off the worker's line,
    or the distance when the worker stands or the station lies behind) and the time to
    reach it at the closing speed (/ 3 s, at most 1)."""
    st = rel[..., TRACK_VALUES + k * PER_STATION : TRACK_VALUES + (k + 1) * PER_STATION]
    known, dist, closing, cos, sin = st[..., 0:1], st[..., 1:2], st[..., 2:3], st[..., 4:5], st[..., 5:6]
    off_line = known * torch.where(cos > 0, dist * sin.abs(), dist)
    eta = torch.where(closing > 0.1, dist * 10 / closing.clamp(min=0.1), torch.full_like(dist, 30.0)) / 30
    return torch.cat([st, off_line, known * eta.clamp(max=1.0)], -1)


class PeerSetScorer(StationScorer):
    """A StationScorer whose collective input also holds one relation block per peer
    heard ([B, F, P, RELATIONS], agent/src/floor/relations.rs `peer_set`: that peer's
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
        present = peers[..., 0:1]  # [B, F, P, 1]: a peer's block starts with 1
        count = present.sum(2)
        stations = []
        for k, own in enumerate(self.station_rows(x)):
            h = self.phi(torch.cat([peers[..., :TRACK_VALUES], station_values(peers, k)], -1)) * present
            mean = h.sum(2) / count.clamp(min=1)
            top = h.max(2).values  # phi's output is >= 0, so the empty slots' zeros never win
            stations.append(torch.cat([own, mean, top, count / self.slots], -1))
        return self.score(stations)


class FacingScorer(StationScorer):
    """A StationScorer over rows that end with the facing block (agent/src/floor/
    relations.rs `facing`: [known], then per station [cos, sin] of its bearing relative
    to where the worker's body faces). Each station's row gains its own two values and
    the known flag, so the rule learned holds for every station alike."""

    def __init__(self, horizon, **kw):
        super().__init__(horizon, extra=3, **kw)

    def forward(self, x):
        rows = self.station_rows(x[..., : KEYPOINTS + RELATIONS])
        face = x[..., KEYPOINTS + RELATIONS : KEYPOINTS + RELATIONS + FACING]
        known = face[..., 0:1]
        return self.score([torch.cat([row, known, face[..., 1 + 2 * k : 3 + 2 * k]], -1) for k, row in enumerate(rows)])
