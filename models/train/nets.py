"""The networks, with exactly the ONNX interface the daemon's manifest check expects.

- GCN (paper II-C): two graph convolutions over the normalised adjacency,
  1024 -> hidden -> 128, the worker (node 0) embedding, and a linear head to 4 logits.
- TemporalGRU (paper II-D): one GRU over [frames, D] rows (D = 162 ego, 290 collective),
  final hidden state -> logits for t and each of the next H ticks.
- Cnn1dGRU (the paper's 1D-CNN baseline): five 1-D convolutions over the worker node's
  1024-d feature of each frame -> 128, concatenated with the keypoints, then the same GRU.
"""
import torch
from torch import nn

from data import CLASSES, EMBEDDING, FEATURE, KEYPOINTS


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
