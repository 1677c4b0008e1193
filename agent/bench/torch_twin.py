#!/usr/bin/env python3
"""PyTorch twin of the SSR driving network in ``agent/src/model`` (crate ssr-agent, Burn 0.22),
for speed comparisons with ``ssr-agent bench``.

Interpreter: ``python3`` (pyenv CPython 3.11 at /root/.pyenv/versions/3.11.7, where
``python3 -m pip install torch numpy`` put torch; no venv is needed on this machine).

    python3 agent/bench/torch_twin.py --config cpu-default --batch 1
    python3 agent/bench/torch_twin.py --config cpu-default --batch 8 --train --iters 5

Every class below mirrors one Rust module (same layer widths, same tensor shapes, batch-first,
same op order, the same initialisers where that is cheap). PyTorch's idiomatic equivalents are
used where the Burn code has to build something by hand:

- bilinear sampling (``sampling.rs``, four row gathers in Burn) is ``F.grid_sample`` (bilinear,
  zero padding, ``align_corners=False``) with grid ``2 * location - 1``: the same semantics;
- Burn's ``Gru`` with ``reset_after = true``, run for one step, is ``nn.GRUCell``;
- Burn's ``MultiHeadAttention`` is ``nn.MultiheadAttention(batch_first=True, dropout=0)``;
- the FFP's plain layer norm is ``F.layer_norm`` without weight and bias (eps 1e-5).

The geometry (camera reference points and hits, previous-BEV alignment points, can-bus) is
computed as ``agent/src/model/bev/grid.rs`` does, for TCP's front camera (CARLA x -1.5, z 2.0,
900x256, fov 100) and a small fixed ego motion, so the sampling touches the same places.

Training step (``--train``): forward (backbone, BEV encoder, STL, head) + FFP + loss + backward +
AdamW(lr 1e-4, weight decay 0.01). The loss (no ``train/loss.rs`` existed when this was written)
is L1 on waypoints + KL(expert Beta || student Beta) for the current and future [acc, steer]
actions + 0.05 * L1 speed + MSE(FFP's predicted future BEV, detached future BEV). The future BEV
is, by default, the network's own BEV of a second ("future") frame computed under
``torch.no_grad`` as SSR does (``--future-bev encode``); ``--future-bev input`` takes a given
random tensor instead (no second encoder pass).

Output: one JSON line with the median and minimum time per iteration and, for forward mode, the
median time of each stage of ``SsrModel::forward`` (backbone, bev_encoder, stl, head).
"""

import argparse
import json
import math
import os
import statistics
import subprocess
import time

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

# ---------------------------------------------------------------------------------------------
# config.rs
# ---------------------------------------------------------------------------------------------

def load_config(spec):
    """A model config: a JSON file, or a preset name resolved by ``ssr-agent config NAME`` so the
    twin always uses the Rust presets (set SSR_AGENT_BIN if the binary is elsewhere)."""
    if os.path.exists(spec):
        with open(spec) as f:
            return json.load(f)
    binary = os.environ.get("SSR_AGENT_BIN", "target/release/ssr-agent")
    out = subprocess.run([binary, "config", spec], check=True, capture_output=True, text=True)
    return json.loads(out.stdout)


MAX_CAMERAS = 6  # camera.rs
COMMANDS = 6  # stl.rs
TARGET_SCALE = 25.0  # stl.rs
SPEED_SCALE = 12.0  # tcp_head.rs
BETA_FLOOR = 1e-3  # tcp_head.rs
CAN_BUS_DIM = 5  # bev/grid.rs
BEHIND_CAMERA = -4.0  # bev/grid.rs
SLOTS = 2  # bev/temporal.rs


# ---------------------------------------------------------------------------------------------
# init.rs
# ---------------------------------------------------------------------------------------------

def xavier_linear(d_in, d_out):
    """Xavier-uniform weights, zero bias."""
    linear = nn.Linear(d_in, d_out)
    nn.init.xavier_uniform_(linear.weight)
    nn.init.zeros_(linear.bias)
    return linear


def constant_linear(d_in, d_out, bias):
    """Zero weights and the given bias."""
    linear = nn.Linear(d_in, d_out)
    nn.init.zeros_(linear.weight)
    with torch.no_grad():
        linear.bias.copy_(torch.as_tensor(bias, dtype=torch.float32))
    return linear


def deformable_offsets(d_in, groups, heads, points):
    """BEVFormer's circular initial offsets; output layout [groups, heads, points, 2]."""
    bias = []
    for _ in range(groups):
        for head in range(heads):
            angle = 2.0 * math.pi * head / heads
            s, c = math.sin(angle), math.cos(angle)
            scale = max(abs(c), abs(s))
            for point in range(points):
                k = float(point + 1)
                bias.extend([c / scale * k, s / scale * k])
    return constant_linear(d_in, groups * heads * points * 2, bias)


def gru_cell(input_size, hidden_size):
    """Burn's Gru (reset_after) as a GRUCell, weights Xavier-normal per gate as Burn's default."""
    cell = nn.GRUCell(input_size, hidden_size)
    with torch.no_grad():
        for weight in (cell.weight_ih, cell.weight_hh):
            for gate in weight.chunk(3, 0):
                nn.init.xavier_normal_(gate)
    return cell


# ---------------------------------------------------------------------------------------------
# sampling.rs
# ---------------------------------------------------------------------------------------------

def bilinear_sample(values, height, width, locations):
    """`values` [N, H*W, C] (row-major (y, x)) at `locations` [N, L, 2] (normalised (x, y)) -> [N, L, C]."""
    n, _, c = values.shape
    maps = values.transpose(1, 2).reshape(n, c, height, width)
    grid = (2.0 * locations - 1.0).unsqueeze(2)  # [N, L, 1, 2]
    sampled = F.grid_sample(maps, grid, mode="bilinear", padding_mode="zeros", align_corners=False)
    return sampled.squeeze(3).transpose(1, 2)


def deformable_aggregate(values, height, width, locations, weights):
    """`values` [N, H*W, C] sampled at `locations` [N, Q, P, 2], summed over P with `weights`
    [N, Q, P] -> [N, Q, C]."""
    n, _, c = values.shape
    maps = values.transpose(1, 2).reshape(n, c, height, width)
    sampled = F.grid_sample(maps, 2.0 * locations - 1.0, mode="bilinear", padding_mode="zeros", align_corners=False)
    return (sampled * weights.unsqueeze(1)).sum(3).transpose(1, 2)  # [N, C, Q, P] -> [N, Q, C]


# ---------------------------------------------------------------------------------------------
# backbone.rs
# ---------------------------------------------------------------------------------------------

class ConvBn(nn.Module):
    """Convolution (no bias, 'same' padding) followed by batch norm."""

    def __init__(self, cin, cout, kernel, stride):
        super().__init__()
        self.conv = nn.Conv2d(cin, cout, kernel, stride=stride, padding=kernel // 2, bias=False)
        self.bn = nn.BatchNorm2d(cout)

    def forward(self, x):
        return self.bn(self.conv(x))


class BasicBlock(nn.Module):
    """ResNet basic block: two 3x3 conv-BN with a (projected) shortcut."""

    def __init__(self, cin, cout, stride):
        super().__init__()
        self.first = ConvBn(cin, cout, 3, stride)
        self.second = ConvBn(cout, cout, 3, 1)
        self.shortcut = ConvBn(cin, cout, 1, stride) if (stride != 1 or cin != cout) else None

    def forward(self, x):
        residual = self.shortcut(x) if self.shortcut is not None else x
        y = self.second(F.relu(self.first(x)))
        return F.relu(y + residual)


class Backbone(nn.Module):
    """ResNet trunk plus neck (1x1 lateral conv then 3x3 conv)."""

    def __init__(self, config):
        super().__init__()
        b = config["backbone"]
        blocks = []
        cin = b["stem_width"]
        for count, width, stride in zip(b["blocks"], b["widths"], b["strides"]):
            for index in range(count):
                blocks.append(BasicBlock(cin, width, stride if index == 0 else 1))
                cin = width
        c = config["channels"]
        self.stem = ConvBn(3, b["stem_width"], 7, 2)
        self.pool = nn.MaxPool2d(3, stride=2, padding=1)
        self.blocks = nn.Sequential(*blocks)
        self.lateral = nn.Conv2d(cin, c, 1)
        self.smooth = nn.Conv2d(c, c, 3, padding=1)

    def forward(self, images):
        x = self.pool(F.relu(self.stem(images)))
        x = self.blocks(x)
        return self.smooth(self.lateral(x))


# ---------------------------------------------------------------------------------------------
# transformer.rs
# ---------------------------------------------------------------------------------------------

class SelfAttentionLayer(nn.Module):
    """Post-norm layer: self-attention (pos on queries and keys) -> LN -> FFN -> LN."""

    def __init__(self, channels, heads, ffn_dim):
        super().__init__()
        self.attention = nn.MultiheadAttention(channels, heads, dropout=0.0, batch_first=True)
        with torch.no_grad():  # Burn: one Xavier-uniform linear each for query, key, value, output
            for weight in self.attention.in_proj_weight.chunk(3, 0):
                nn.init.xavier_uniform_(weight)
            nn.init.xavier_uniform_(self.attention.out_proj.weight)
        self.norm_attention = nn.LayerNorm(channels)
        self.ffn_in = xavier_linear(channels, ffn_dim)
        self.ffn_out = xavier_linear(ffn_dim, channels)
        self.norm_ffn = nn.LayerNorm(channels)

    def forward(self, x, pos=None):
        query_key = x + pos if pos is not None else x
        attended, _ = self.attention(query_key, query_key, x, need_weights=False)
        x = self.norm_attention(x + attended)
        ffn = self.ffn_out(F.relu(self.ffn_in(x)))
        return self.norm_ffn(x + ffn)


def run_layers(layers, x, pos=None):
    for layer in layers:
        x = layer(x, pos)
    return x


# ---------------------------------------------------------------------------------------------
# bev/temporal.rs
# ---------------------------------------------------------------------------------------------

class TemporalSelfAttention(nn.Module):
    """Deformable attention over two slots: the aligned previous BEV and the current queries."""

    def __init__(self, channels, heads, points):
        super().__init__()
        self.offsets = deformable_offsets(2 * channels, SLOTS, heads, points)
        self.weights = constant_linear(2 * channels, SLOTS * heads * points, [0.0] * (SLOTS * heads * points))
        self.value_proj = xavier_linear(channels, channels)
        self.output_proj = xavier_linear(channels, channels)
        self.heads = heads
        self.points = points

    def forward(self, query, pos, aligned_previous, has_previous, reference, rows, cols):
        b, q, c = query.shape
        heads, points = self.heads, self.points
        head_dim = c // heads
        previous = aligned_previous * has_previous + query * (1.0 - has_previous)
        context = torch.cat([previous, query + pos], 2)

        scale = query.new_tensor([1.0 / cols, 1.0 / rows]).reshape(1, 1, 1, 1, 1, 2)
        offsets = self.offsets(context).reshape(b, q, SLOTS, heads, points, 2).permute(0, 2, 3, 1, 4, 5) * scale
        locations = (offsets + reference.reshape(1, 1, 1, q, 1, 2)).reshape(b * SLOTS * heads, q, points, 2)
        weights = (
            F.softmax(self.weights(context).reshape(b, q, SLOTS, heads, points), 4)
            .permute(0, 2, 3, 1, 4)
            .reshape(b * SLOTS * heads, q, points)
        )
        values = (
            self.value_proj(torch.stack([previous, query], 1))
            .reshape(b * SLOTS, q, heads, head_dim)
            .transpose(1, 2)
            .reshape(b * SLOTS * heads, q, head_dim)
        )
        sampled = (
            deformable_aggregate(values, rows, cols, locations, weights)
            .reshape(b, SLOTS, heads, q, head_dim)
            .mean(1)
            .transpose(1, 2)
            .reshape(b, q, c)
        )
        return query + self.output_proj(sampled)


# ---------------------------------------------------------------------------------------------
# bev/spatial.rs
# ---------------------------------------------------------------------------------------------

class SpatialCrossAttention(nn.Module):
    """Deformable attention around each pillar point's projection, averaged over seeing cameras."""

    def __init__(self, channels, heads, anchors, points):
        super().__init__()
        self.offsets = deformable_offsets(channels, 1, heads, points)
        self.weights = constant_linear(channels, heads * points, [0.0] * (heads * points))
        self.value_proj = xavier_linear(channels, channels)
        self.output_proj = xavier_linear(channels, channels)
        self.heads = heads
        self.anchors = anchors
        self.points_per_anchor = points // anchors

    def forward(self, query, pos, features, camera_points, camera_hits):
        values_in, height, width, cams = features
        b, q, c = query.shape
        heads, anchors, per_anchor = self.heads, self.anchors, self.points_per_anchor
        points = anchors * per_anchor
        head_dim = c // heads
        with_pos = query + pos

        scale = query.new_tensor([1.0 / width, 1.0 / height]).reshape(1, 1, 1, 1, 1, 1, 2)
        offsets = (
            self.offsets(with_pos)
            .reshape(b, q, heads, anchors, per_anchor, 2)
            .permute(0, 2, 1, 3, 4, 5)
            .unsqueeze(1)
            * scale
        )
        reference = camera_points.reshape(b, cams, 1, q, anchors, 1, 2)
        locations = (reference + offsets).reshape(b * cams * heads, q, points, 2)
        weights = (
            F.softmax(self.weights(with_pos).reshape(b, q, heads, points), 3)
            .permute(0, 2, 1, 3)
            .unsqueeze(1)
            .expand(b, cams, heads, q, points)
            .reshape(b * cams * heads, q, points)
        )
        hw = height * width
        values = (
            self.value_proj(values_in)
            .reshape(b * cams, hw, heads, head_dim)
            .transpose(1, 2)
            .reshape(b * cams * heads, hw, head_dim)
        )
        sampled = (
            deformable_aggregate(values, height, width, locations, weights)
            .reshape(b, cams, heads, q, head_dim)
            .permute(0, 1, 3, 2, 4)
            .reshape(b, cams, q, c)
        )
        hits = camera_hits.unsqueeze(3)
        count = hits.sum(1).clamp_min(1.0)
        mean = (sampled * hits).sum(1) / count
        return query + self.output_proj(mean)


# ---------------------------------------------------------------------------------------------
# bev/mod.rs
# ---------------------------------------------------------------------------------------------

class EncoderLayer(nn.Module):
    """TSA -> LN -> SCA -> LN -> FFN -> LN."""

    def __init__(self, config):
        super().__init__()
        c, bev = config["channels"], config["bev"]
        self.temporal = TemporalSelfAttention(c, bev["heads"], bev["temporal_points"])
        self.norm_temporal = nn.LayerNorm(c)
        self.spatial = SpatialCrossAttention(c, bev["heads"], len(bev["pillar_heights"]), bev["spatial_points"])
        self.norm_spatial = nn.LayerNorm(c)
        self.ffn_in = xavier_linear(c, bev["ffn_dim"])
        self.ffn_out = xavier_linear(bev["ffn_dim"], c)
        self.norm_ffn = nn.LayerNorm(c)

    def forward(self, query, pos, aligned, has_previous, grid_points, rows, cols, features, camera_points, camera_hits):
        query = self.norm_temporal(self.temporal(query, pos, aligned, has_previous, grid_points, rows, cols))
        query = self.norm_spatial(self.spatial(query, pos, features, camera_points, camera_hits))
        ffn = self.ffn_out(F.relu(self.ffn_in(query)))
        return self.norm_ffn(query + ffn)


def reference_points(rows, cols):
    """Normalised centres of the grid's cells, [1, Q, 2]."""
    i = torch.arange(rows * cols)
    u = ((i % cols).float() + 0.5) / cols
    v = ((i // cols).float() + 0.5) / rows
    return torch.stack([u, v], 1).unsqueeze(0)


class BevEncoder(nn.Module):
    """Learned BEV queries + position + can-bus, refined by encoder layers."""

    def __init__(self, config):
        super().__init__()
        c, bev = config["channels"], config["bev"]
        self.rows, self.cols = bev["rows"], bev["cols"]
        self.queries = nn.Parameter(torch.randn(self.rows * self.cols, c))
        self.row_embed = nn.Parameter(torch.rand(self.rows, c // 2))
        self.col_embed = nn.Parameter(torch.rand(self.cols, c // 2))
        self.camera_embed = nn.Parameter(torch.randn(MAX_CAMERAS, c))
        self.can_bus_in = xavier_linear(CAN_BUS_DIM, c // 2)
        self.can_bus_out = xavier_linear(c // 2, c)
        self.can_bus_norm = nn.LayerNorm(c)
        self.layers = nn.ModuleList(EncoderLayer(config) for _ in range(bev["layers"]))
        self.register_buffer("grid_points", reference_points(self.rows, self.cols), persistent=False)

    def positions(self):
        """[1, Q, C]: [column embedding, row embedding] per cell."""
        rows, cols = self.rows, self.cols
        half = self.col_embed.shape[1]
        col = self.col_embed.unsqueeze(0).expand(rows, cols, half)
        row = self.row_embed.unsqueeze(1).expand(rows, cols, half)
        return torch.cat([col, row], 2).reshape(1, rows * cols, 2 * half)

    def image_features(self, features, cameras):
        """[B * cameras, C, h, w] -> (values [B * cameras, h * w, C] + camera embedding, h, w, cameras)."""
        bn, c, h, w = features.shape
        embed = self.camera_embed[:cameras].reshape(1, cameras, 1, c)
        values = features.reshape(bn // cameras, cameras, c, h * w).transpose(2, 3) + embed
        return values.reshape(bn, h * w, c), h, w, cameras

    def forward(self, features, geometry, previous_bev):
        b = previous_bev.shape[0]
        pos = self.positions()
        aligned = bilinear_sample(previous_bev, self.rows, self.cols, geometry["previous_points"])
        can_bus = self.can_bus_norm(F.relu(self.can_bus_out(F.relu(self.can_bus_in(geometry["can_bus"])))))
        query = self.queries.unsqueeze(0).repeat(b, 1, 1) + can_bus.unsqueeze(1)
        for layer in self.layers:
            query = layer(
                query, pos, aligned, geometry["has_previous"], self.grid_points, self.rows, self.cols,
                features, geometry["camera_points"], geometry["camera_hits"],
            )
        return query


# ---------------------------------------------------------------------------------------------
# stl.rs
# ---------------------------------------------------------------------------------------------

class NavigationGate(nn.Module):
    """Channel gate from [command one-hot, target point / 25]."""

    def __init__(self, channels):
        super().__init__()
        self.fc_in = xavier_linear(COMMANDS + 2, channels)
        self.fc_out = xavier_linear(channels, channels)

    def forward(self, command, target_point):
        navigation = torch.cat([command, target_point / TARGET_SCALE], 1)
        return torch.sigmoid(self.fc_out(F.relu(self.fc_in(navigation))))


class TokenLearner(nn.Module):
    """Spatial attention maps from a small MLP over group-normalised features."""

    def __init__(self, channels, bottleneck, tokens):
        super().__init__()
        self.norm = nn.GroupNorm(1, channels, eps=1e-6)
        self.fc_in = xavier_linear(channels, bottleneck)
        self.fc_out = xavier_linear(bottleneck, tokens)

    def forward(self, x):
        normalised = self.norm(x.transpose(1, 2)).transpose(1, 2)
        logits = self.fc_out(F.gelu(self.fc_in(normalised)))
        attention = F.softmax(logits.transpose(1, 2), 2)
        return attention @ x, attention


class SceneTokenLearner(nn.Module):
    """Navigation gate -> TokenLearner over [gated BEV, position] -> self-attention over tokens."""

    def __init__(self, config):
        super().__init__()
        c, t = config["channels"], config["tokens"]
        self.gate = NavigationGate(c)
        self.learner = TokenLearner(2 * c, t["bottleneck"], t["num_tokens"])
        self.layers = nn.ModuleList(SelfAttentionLayer(c, t["heads"], t["ffn_dim"]) for _ in range(t["layers"]))

    def forward(self, bev, pos, command, target_point):
        b, q, c = bev.shape
        gate = self.gate(command, target_point)
        gated = bev * gate.unsqueeze(1)
        tokens, attention = self.learner(torch.cat([gated, pos.expand(b, q, c)], 2))
        content, token_pos = tokens[:, :, :c], tokens[:, :, c:]
        tokens = run_layers(self.layers, content, token_pos)
        return tokens, attention, gate


# ---------------------------------------------------------------------------------------------
# tcp_head.rs
# ---------------------------------------------------------------------------------------------

class Mlp(nn.Module):
    """Linear layers with ReLU after each."""

    def __init__(self, widths):
        super().__init__()
        self.layers = nn.ModuleList(xavier_linear(a, b) for a, b in zip(widths[:-1], widths[1:]))

    def forward(self, x):
        for layer in self.layers:
            x = F.relu(layer(x))
        return x


class BetaPolicy(nn.Module):
    """Policy trunk and Beta parameter heads for [acceleration, steer]."""

    def __init__(self, width):
        super().__init__()
        self.trunk = Mlp([width, width, width])
        self.alpha = xavier_linear(width, 2)
        self.beta = xavier_linear(width, 2)

    def forward(self, x):
        h = self.trunk(x)
        return F.softplus(self.alpha(h)) + BETA_FLOOR, F.softplus(self.beta(h)) + BETA_FLOOR


def pool(weights, tokens):
    """Attention-weighted mean: weights [B, S], tokens [B, S, C] -> [B, C]."""
    return (weights.unsqueeze(1) @ tokens).squeeze(1)


class TcpHead(nn.Module):
    """TCP's trajectory and (multi-step) control branches over the scene tokens."""

    def __init__(self, config):
        super().__init__()
        c, h = config["channels"], config["head"]
        m, hid, state = h["measurement_dim"], h["hidden_dim"], h["state_dim"]
        tokens = config["tokens"]["num_tokens"]
        self.measurements = Mlp([3 + COMMANDS, m, m])
        self.speed = Mlp([c, hid, hid])
        self.speed_out = xavier_linear(hid, 1)
        self.join_trajectory = Mlp([c + m, hid, hid, state])
        self.trajectory_gru = gru_cell(4, state)
        self.waypoint_out = xavier_linear(state, 2)
        self.initial_attention = Mlp([m, hid])
        self.initial_attention_out = xavier_linear(hid, tokens)
        self.join_control = Mlp([c + m, hid, hid, state])
        self.policy = BetaPolicy(state)
        self.control_gru = gru_cell(state + 4, state)
        self.guided_attention = Mlp([2 * state, hid])
        self.guided_attention_out = xavier_linear(hid, tokens)
        self.merge = Mlp([state + c, hid])
        self.merge_out = xavier_linear(hid, state)
        self.step = Mlp([state, state, state])
        self.pred_len = h["pred_len"]

    def forward(self, tokens, speed, target_point, command):
        b = tokens.shape[0]
        measurements = self.measurements(torch.cat([speed / SPEED_SCALE, target_point, command], 1))
        global_ = tokens.mean(1)
        predicted_speed = self.speed_out(self.speed(global_))

        # Trajectory branch.
        hidden = self.join_trajectory(torch.cat([global_, measurements], 1))
        position = tokens.new_zeros(b, 2)
        waypoints, trajectory_states = [], []
        for _ in range(self.pred_len):
            hidden = self.trajectory_gru(torch.cat([position, target_point], 1), hidden)
            position = position + self.waypoint_out(hidden)
            waypoints.append(position)
            trajectory_states.append(hidden)

        # Control branch: current step.
        attention = F.softmax(self.initial_attention_out(self.initial_attention(measurements)), 1)
        pooled = pool(attention, tokens)
        feature = self.join_control(torch.cat([pooled, measurements], 1))
        alpha, beta = self.policy(feature)

        # Multi-step control, guided by the trajectory states.
        step_alpha, step_beta = alpha, beta
        state = torch.zeros_like(feature)
        future_alpha, future_beta = [], []
        for trajectory_state in trajectory_states:
            state = self.control_gru(torch.cat([feature, step_alpha, step_beta], 1), state)
            guide = F.softmax(
                self.guided_attention_out(self.guided_attention(torch.cat([state, trajectory_state], 1))), 1
            )
            merged = self.merge_out(self.merge(torch.cat([state, pool(guide, tokens)], 1)))
            feature = feature + self.step(merged)
            step_alpha, step_beta = self.policy(feature)
            future_alpha.append(step_alpha)
            future_beta.append(step_beta)

        return dict(
            waypoints=torch.stack(waypoints, 1),
            alpha=alpha,
            beta=beta,
            future_alpha=torch.stack(future_alpha, 1),
            future_beta=torch.stack(future_beta, 1),
            speed=predicted_speed,
            control_attention=attention,
        )


# ---------------------------------------------------------------------------------------------
# ffp.rs
# ---------------------------------------------------------------------------------------------

class MotionLayerNorm(nn.Module):
    """Non-affine layer norm modulated by gamma and beta from the flattened trajectory."""

    def __init__(self, condition, channels):
        super().__init__()
        self.reduce = xavier_linear(condition, channels)
        self.gamma = constant_linear(channels, channels, [1.0] * channels)
        self.beta = constant_linear(channels, channels, [0.0] * channels)

    def forward(self, tokens, condition):
        h = F.relu(self.reduce(condition))
        gamma = self.gamma(h).unsqueeze(1)
        beta = self.beta(h).unsqueeze(1)
        return F.layer_norm(tokens, tokens.shape[-1:], eps=1e-5) * gamma + beta


class TokenFuser(nn.Module):
    """Tokens back to a dense BEV with sigmoid mixing weights from the current BEV."""

    def __init__(self, channels, tokens, slots):
        super().__init__()
        self.norm_tokens = nn.GroupNorm(1, channels, eps=1e-6)
        self.expand = xavier_linear(tokens, slots)
        self.norm_slots = nn.GroupNorm(1, channels, eps=1e-6)
        self.norm_bev = nn.GroupNorm(1, channels, eps=1e-6)
        self.mix_in = xavier_linear(channels, slots)
        self.mix_out = xavier_linear(slots, slots)

    def forward(self, tokens, bev):
        slots = self.norm_slots(self.expand(self.norm_tokens(tokens.transpose(1, 2))))  # [B, C, slots]
        bev = self.norm_bev(bev.transpose(1, 2)).transpose(1, 2)
        mix = torch.sigmoid(self.mix_out(F.gelu(self.mix_in(bev))))  # [B, Q, slots]
        return mix @ slots.transpose(1, 2)


class FutureFeaturePredictor(nn.Module):
    """MLN -> latent world model (self-attention, no position) -> TokenFuser."""

    def __init__(self, config):
        super().__init__()
        c, t = config["channels"], config["tokens"]
        self.motion_norm = MotionLayerNorm(2 * config["head"]["pred_len"], c)
        self.world_model = nn.ModuleList(
            SelfAttentionLayer(c, t["heads"], t["ffn_dim"]) for _ in range(config["ffp"]["layers"])
        )
        self.fuser = TokenFuser(c, t["num_tokens"], config["ffp"]["fuser_slots"])

    def forward(self, tokens, waypoints, bev):
        b, p, _ = waypoints.shape
        dreamed = self.motion_norm(tokens, waypoints.reshape(b, 2 * p))
        future_tokens = run_layers(self.world_model, dreamed, None)
        return self.fuser(future_tokens, bev)


# ---------------------------------------------------------------------------------------------
# mod.rs
# ---------------------------------------------------------------------------------------------

class SsrModel(nn.Module):
    """Backbone -> BEV encoder -> Scenes TokenLearner -> TCP head; plus the FFP (training)."""

    def __init__(self, config):
        super().__init__()
        self.backbone = Backbone(config)
        self.bev = BevEncoder(config)
        self.stl = SceneTokenLearner(config)
        self.head = TcpHead(config)
        self.ffp = FutureFeaturePredictor(config)

    def image_features(self, images):
        return self.backbone(images)

    def encode_bev(self, features, inputs):
        features = self.bev.image_features(features, inputs["cameras"])
        return self.bev(features, inputs["geometry"], inputs["previous_bev"])

    def plan(self, bev, inputs):
        tokens, attention, gate = self.stl(bev, self.bev.positions(), inputs["command"], inputs["target_point"])
        head = self.head(tokens, inputs["speed"], inputs["target_point"], inputs["command"])
        return (tokens, attention, gate), head

    def forward(self, inputs):
        bev = self.encode_bev(self.image_features(inputs["images"]), inputs)
        scene, head = self.plan(bev, inputs)
        return bev, scene, head

    def predict_future_bev(self, bev, scene, head):
        return self.ffp(scene[0], head["waypoints"], bev)


# ---------------------------------------------------------------------------------------------
# Geometry (bev/grid.rs, camera.rs, pose.rs) for TCP's front camera
# ---------------------------------------------------------------------------------------------

class TcpFrontProjector:
    """camera.rs's pinhole projection for CameraSpec::tcp_front (CARLA x -1.5, z 2.0, no rotation)."""

    width, height, fov = 900.0, 256.0, 100.0

    def __init__(self):
        self.focal = self.width / (2.0 * math.tan(math.radians(self.fov) / 2.0))
        self.position = np.array([-1.5, 0.0, 2.0])
        # Zero rotation: forward = x, right = CARLA +y = ego -y, up = z.
        self.forward, self.right, self.up = np.array([1.0, 0, 0]), np.array([0, -1.0, 0]), np.array([0, 0, 1.0])

    def project(self, points):
        """Ego points [..., 3] -> pixels [..., 2] and an in-front mask (depth > 1e-5)."""
        d = points - self.position
        depth = d @ self.forward
        safe = np.where(depth > 1e-5, depth, 1.0)
        u = self.width / 2.0 + self.focal * (d @ self.right) / safe
        v = self.height / 2.0 - self.focal * (d @ self.up) / safe
        return np.stack([u, v], -1), depth > 1e-5


def sample_geometry(config, motion=(0.5, 0.05, 0.01), speed=6.0):
    """SampleGeometry::new for Rig::tcp() and a small ego motion: numpy arrays of one sample."""
    bev = config["bev"]
    rows, cols = bev["rows"], bev["cols"]
    x_min, x_max, y_min, y_max = bev["x_min"], bev["x_max"], bev["y_min"], bev["y_max"]
    i = np.arange(rows * cols)
    row, col = i // cols, i % cols
    x = x_max - (row + 0.5) * (x_max - x_min) / rows
    y = y_max - (col + 0.5) * (y_max - y_min) / cols
    heights = np.asarray(bev["pillar_heights"])
    points = np.stack(np.broadcast_arrays(x[:, None], y[:, None], heights[None, :]), -1)  # [Q, Z, 3]
    projector = TcpFrontProjector()
    pixels, in_front = projector.project(points)
    normalised = pixels / np.array([projector.width, projector.height])
    inside = in_front & np.all((normalised >= 0.0) & (normalised < 1.0), -1)
    camera_points = np.where(in_front[..., None], normalised, BEHIND_CAMERA)  # [Q, Z, 2]
    camera_hits = inside.any(1).astype(np.float32)  # [Q]

    dx, dy, dyaw = motion
    s, c = math.sin(dyaw), math.cos(dyaw)
    px, py = c * x - s * y + dx, s * x + c * y + dy  # EgoMotion::to_previous
    previous_points = np.stack([(y_max - py) / (y_max - y_min), (x_max - px) / (x_max - x_min)], -1)
    can_bus = np.array([dx, dy, dyaw, speed / 12.0, 1.0])
    return camera_points, camera_hits, previous_points, can_bus


def make_inputs(config, batch, device, cameras=1):
    """A batch of identical geometries with random images, BEV history and measurements."""
    camera_points, camera_hits, previous_points, can_bus = sample_geometry(config)
    q, z = camera_points.shape[:2]
    t = lambda a: torch.as_tensor(np.ascontiguousarray(a), dtype=torch.float32, device=device)  # noqa: E731
    geometry = dict(
        camera_points=t(camera_points).expand(batch * cameras, q, z, 2).contiguous(),
        camera_hits=t(camera_hits).expand(batch, cameras, q).contiguous(),
        previous_points=t(previous_points).expand(batch, q, 2).contiguous(),
        has_previous=torch.ones(batch, 1, 1, device=device),
        can_bus=t(can_bus).expand(batch, CAN_BUS_DIM).contiguous(),
    )
    command = F.one_hot(torch.randint(0, COMMANDS, (batch,)), COMMANDS).float().to(device)
    return dict(
        images=torch.randn(batch * cameras, 3, config["image_height"], config["image_width"], device=device),
        cameras=cameras,
        geometry=geometry,
        previous_bev=torch.randn(batch, q, config["channels"], device=device),
        speed=torch.rand(batch, 1, device=device) * 8.0,
        target_point=torch.randn(batch, 2, device=device) * 10.0 + torch.tensor([20.0, 0.0], device=device),
        command=command,
    )


def make_targets(config, batch, device):
    p = config["head"]["pred_len"]
    q = config["bev"]["rows"] * config["bev"]["cols"]
    positive = lambda *shape: torch.rand(*shape, device=device) * 4.0 + 0.5  # noqa: E731
    return dict(
        waypoints=torch.cumsum(torch.rand(batch, p, 2, device=device), 1),
        alpha=positive(batch, 2),
        beta=positive(batch, 2),
        future_alpha=positive(batch, p, 2),
        future_beta=positive(batch, p, 2),
        speed=torch.rand(batch, 1, device=device),
        future_images=torch.randn(batch, 3, config["image_height"], config["image_width"], device=device),
        future_bev=torch.randn(batch, q, config["channels"], device=device),
    )


# ---------------------------------------------------------------------------------------------
# Loss and timing
# ---------------------------------------------------------------------------------------------

def beta_kl(expert_alpha, expert_beta, alpha, beta):
    """Mean KL(Beta(expert) || Beta(student))."""
    expert = torch.distributions.Beta(expert_alpha, expert_beta)
    student = torch.distributions.Beta(alpha, beta)
    return torch.distributions.kl_divergence(expert, student).mean()


def training_loss(model, inputs, targets, future_bev_mode):
    bev, scene, head = model(inputs)
    predicted_future = model.predict_future_bev(bev, scene, head)
    if future_bev_mode == "encode":
        with torch.no_grad():
            future_inputs = dict(inputs, images=targets["future_images"], previous_bev=bev.detach())
            future_bev = model.encode_bev(model.image_features(future_inputs["images"]), future_inputs)
    else:
        future_bev = targets["future_bev"]
    return (
        F.l1_loss(head["waypoints"], targets["waypoints"])
        + beta_kl(targets["alpha"], targets["beta"], head["alpha"], head["beta"])
        + beta_kl(targets["future_alpha"], targets["future_beta"], head["future_alpha"], head["future_beta"])
        + 0.05 * F.l1_loss(head["speed"], targets["speed"])
        + F.mse_loss(predicted_future, future_bev.detach())
    )


def timed_forward(model, inputs, sync):
    """SsrModel::forward split into its four stages; returns seconds per stage."""
    t0 = time.perf_counter()
    features = model.image_features(inputs["images"])
    sync()
    t1 = time.perf_counter()
    bev = model.encode_bev(features, inputs)
    sync()
    t2 = time.perf_counter()
    tokens, _, _ = model.stl(bev, model.bev.positions(), inputs["command"], inputs["target_point"])
    sync()
    t3 = time.perf_counter()
    model.head(tokens, inputs["speed"], inputs["target_point"], inputs["command"])
    sync()
    t4 = time.perf_counter()
    return dict(backbone=t1 - t0, bev_encoder=t2 - t1, stl=t3 - t2, head=t4 - t3)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", default="cpu-default", help="preset name or config JSON file")
    parser.add_argument("--batch", type=int, default=1)
    parser.add_argument("--iters", type=int, default=20)
    parser.add_argument("--warmup", type=int, default=3)
    parser.add_argument("--train", action="store_true", help="time a full training step instead of inference")
    parser.add_argument("--threads", type=int, default=os.cpu_count())
    parser.add_argument("--device", default="cpu", help="torch device (cpu, cuda)")
    parser.add_argument(
        "--future-bev", choices=["encode", "input"], default="encode",
        help="training target of the FFP: the BEV of a future frame encoded under no_grad, or a given tensor",
    )
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    device = torch.device(args.device)
    sync = (lambda: torch.cuda.synchronize(device)) if device.type == "cuda" else (lambda: None)
    config = load_config(args.config)

    model = SsrModel(config).to(device)
    params = sum(p.numel() for p in model.parameters())
    inputs = make_inputs(config, args.batch, device)

    totals, stages = [], []
    if args.train:
        model.train()
        targets = make_targets(config, args.batch, device)
        optimizer = torch.optim.AdamW(model.parameters(), lr=1e-4, weight_decay=0.01)
        for i in range(args.warmup + args.iters):
            sync()
            start = time.perf_counter()
            optimizer.zero_grad(set_to_none=True)
            loss = training_loss(model, inputs, targets, args.future_bev)
            loss.backward()
            optimizer.step()
            sync()
            if i >= args.warmup:
                totals.append(time.perf_counter() - start)
        if not math.isfinite(loss.item()):
            raise SystemExit(f"training loss is not finite: {loss.item()}")
    else:
        model.eval()
        with torch.inference_mode():
            for i in range(args.warmup + args.iters):
                sync()
                start = time.perf_counter()
                stage = timed_forward(model, inputs, sync)
                if i >= args.warmup:
                    totals.append(time.perf_counter() - start)
                    stages.append(stage)

    ms = lambda seconds: round(1000.0 * seconds, 3)  # noqa: E731
    report = dict(
        framework="pytorch",
        config=args.config,
        batch=args.batch,
        mode="train" if args.train else "forward",
        median_ms=ms(statistics.median(totals)),
        min_ms=ms(min(totals)),
        params=params,
    )
    if stages:
        report["breakdown_ms"] = {k: ms(statistics.median(s[k] for s in stages)) for k in stages[0]}
    print(json.dumps(report))


if __name__ == "__main__":
    main()
