#!/usr/bin/env python3
"""ProcNet in PyTorch: the project's own second implementation of procnet/src/model.rs.

It reads the same safetensors weights (the same parameter names) and the same configuration
(the JSON stored in the weight file's metadata under "config"), so that

  * `reference` prints the outputs the Rust tests compare against
    (procnet/tests/reference.rs embeds the command and the values), and
  * `bench` times a training step and per-frame inference side by side with the Rust
    backends (bench/procnet_bench.py runs both).

Needs torch 2.9.0 and safetensors (pip install torch==2.9.0 safetensors).
"""

import argparse
import json
import sys
import time

import torch
import torch.nn.functional as F
from safetensors import safe_open
from safetensors.torch import load_file


def load(path):
    """Weights and configuration of a ProcNet safetensors file."""
    with safe_open(path, "pt") as f:
        meta = f.metadata() or {}
    if "config" not in meta:
        sys.exit(f"{path}: no 'config' in the metadata: not a workcell ProcNet file")
    return load_file(path), json.loads(meta["config"])


def group_norm(x, groups, weight, bias):
    return F.group_norm(x, groups, weight, bias, eps=1e-5)


def conv(x, P, name, padding=None):
    w = P[name + ".weight"]
    b = P.get(name + ".bias")
    k = w.shape[-1]
    return F.conv2d(x, w, b, padding=k // 2 if padding is None else padding)


class ProcNet:
    """The network as plain functions of a parameter dict (names as in the Rust model)."""

    def __init__(self, P, cfg):
        self.P = P
        self.cfg = cfg
        self.L = len(cfg["repr_channels"])
        self.pred = cfg["prediction_loss"]
        self.delay = cfg["axonal_delay"]
        self.cell = cfg["cell"]
        self.gelu = cfg["decoder_activation"] == "gelu"
        # Absent from weight files written before the switch existed: off.
        self.full_res = cfg.get("decoder_full_resolution", False)

    def norm(self, x, name, groups):
        return group_norm(x, groups, self.P[name + ".weight"], self.P[name + ".bias"])

    def initial_state(self, b, h, w):
        a = self.cfg["input_channels"]
        r = self.cfg["repr_channels"]
        e = [2 * c if self.pred else c for c in a]
        cells = [torch.zeros(b, r[l], h >> l, w >> l) for l in range(self.L)]
        cs = [torch.zeros(b, r[l], h >> l, w >> l) for l in range(self.L)]
        errors = [torch.zeros(b, e[l], h >> l, w >> l) for l in range(self.L)]
        return cells, cs, errors

    def hgru(self, p, x, h):
        P = self.P
        if p + "input.weight" in P:
            x = conv(x, P, p + "input")
        k = h.shape[1]

        def sym(w):
            return 0.5 * (w + w.transpose(0, 1))

        def pc(name):
            return P[p + name].view(1, -1, 1, 1)

        def n(i, y):
            return self.norm(y, f"{p}n{i}", k)

        w_inh, w_exc = sym(P[p + "w_inh"]), sym(P[p + "w_exc"])
        pad = w_inh.shape[-1] // 2
        g1 = torch.sigmoid(n(0, conv(h, P, p + "u1")))
        c1 = n(1, F.conv2d(h * g1, w_inh, padding=pad))
        h1 = F.relu(x - F.relu(c1 * (pc("alpha") * h + pc("mu"))))
        g2 = torch.sigmoid(n(2, conv(h1, P, p + "u2")))
        c2 = n(3, F.conv2d(h1, w_exc, padding=pad))
        h_tilde = F.relu(pc("kappa") * h1 + pc("gamma") * c2 + pc("omega") * h1 * c2)
        return (1 - g2) * h + g2 * h_tilde

    def convlstm(self, p, x, h, c):
        gates = conv(torch.cat([x, h], 1), self.P, p + "gates")
        peep = conv(c, self.P, p + "peephole")
        i, f, g, o = gates.chunk(4, 1)
        pi, pf, po = peep.chunk(3, 1)
        c_new = torch.sigmoid(f + pf) * c + torch.sigmoid(i + pi) * torch.tanh(g)
        return torch.sigmoid(o + po) * torch.tanh(c_new), c_new

    def cell_step(self, l, x, h, c):
        variant = {"hgru": "Hgru", "convlstm": "ConvLstm", "conv": "Conv"}[self.cell]
        p = f"layers.{l}.cell.{variant}."
        if self.cell == "hgru":
            return self.hgru(p, x, h), c
        if self.cell == "convlstm":
            return self.convlstm(p, x, h, c)
        return F.relu(conv(x, self.P, p + "conv")), c

    def step(self, frame, state):
        cells, cs, prev_errors = state
        P = self.P
        errors, pred, pe = [], None, None
        a = frame
        for l in range(self.L):
            if self.pred:
                a_hat = F.relu(conv(cells[l], P, f"layers.{l}.predict"))
                if l == 0:
                    pred = a_hat.clamp(0, 1)
                e = F.relu(torch.cat([a - a_hat, a_hat - a], 1))
                pe = e.mean() if pe is None else pe + e.mean()
            else:
                e = F.relu(a)
            errors.append(e)
            if l + 1 < self.L:
                src = prev_errors[l] if self.delay else e
                a = F.max_pool2d(conv(src, P, f"layers.{l}.up"), 2)
        new_cells, new_cs = [None] * self.L, [None] * self.L
        for l in reversed(range(self.L)):
            if l + 1 == self.L:
                x = errors[l]
            else:
                above = cells[l + 1] if self.delay else new_cells[l + 1]
                x = torch.cat([errors[l], F.interpolate(above, scale_factor=2, mode="nearest")], 1)
            new_cells[l], new_cs[l] = self.cell_step(l, x, cells[l], cs[l])
        logits = self.decode(new_cells)
        return logits, pred, pe, (new_cells, new_cs, errors)

    def decode(self, cells):
        first = 1 if self.pred and not self.full_res else 0
        x = cells[-1]
        for l in reversed(range(self.L - 1)):
            groups = decoder_groups(x.shape[1])
            x = self.norm(x, f"decoder.{l}.norm", groups)
            x = F.conv_transpose2d(x, self.P[f"decoder.{l}.upconv.weight"], stride=2, padding=1,
                                   output_padding=1)
            x = F.gelu(x) if self.gelu else F.relu(x)
            if l >= first:
                x = x + cells[l]
        x = self.norm(x, "head_norm", decoder_groups(x.shape[1]))
        return F.conv2d(x, self.P["head.weight"])


def decoder_groups(c):
    return next(g for g in (8, 4, 2, 1) if c % g == 0)


def reference_input(t, b, h, w):
    """The deterministic test sequence of procnet/tests/reference.rs (same formula)."""
    ti = torch.arange(t, dtype=torch.float64).view(t, 1, 1, 1, 1)
    bi = torch.arange(b, dtype=torch.float64).view(1, b, 1, 1, 1)
    ci = torch.arange(3, dtype=torch.float64).view(1, 1, 3, 1, 1)
    yi = torch.arange(h, dtype=torch.float64).view(1, 1, 1, h, 1)
    xi = torch.arange(w, dtype=torch.float64).view(1, 1, 1, 1, w)
    v = 0.5 + 0.5 * torch.sin(0.37 * xi + 0.23 * yi + 1.1 * ci + 0.5 * ti + 0.7 * bi)
    return v.float()


def cmd_reference(args):
    P, cfg = load(args.weights)
    net = ProcNet(P, cfg)
    s = cfg["input_size"]
    frames = reference_input(args.frames, 1, s, s)
    state = net.initial_state(1, s, s)
    out = {}
    with torch.no_grad():
        for t in range(args.frames):
            logits, pred, pe, state = net.step(frames[t], state)
        probs = torch.sigmoid(logits)
        out["logits_abs_mean_per_class"] = logits.abs().mean(dim=(0, 2, 3)).tolist()
        out["probs_sample"] = [probs[0, c, (7 * c) % s, (11 * c + 3) % s].item()
                               for c in range(probs.shape[1])]
        out["prediction_error"] = None if pe is None else pe.item()
        out["repr_top_mean"] = state[0][-1].mean().item()
    print(json.dumps(out, indent=1))


def cmd_bench(args):
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    P, cfg = load(args.weights)
    s = cfg["input_size"]
    ncls = len(cfg["classes"])
    params = {k: v.clone().requires_grad_(True) for k, v in P.items()}
    net = ProcNet(params, cfg)
    opt = torch.optim.AdamW(params.values(), lr=1e-3)
    b, t = args.batch, args.frames
    x = torch.rand(t, b, 3, s, s)
    y = (torch.rand(t, b, ncls, s, s) > 0.5).float()

    def train_step():
        state = net.initial_state(b, s, s)
        loss = 0
        for i in range(t):
            logits, _, pe, state = net.step(x[i], state)
            if i > 0:
                p = torch.sigmoid(logits)
                inter = (p * y[i]).sum((2, 3))
                dice = 1 - (2 * inter + 1) / (p.sum((2, 3)) + y[i].sum((2, 3)) + 1)
                loss = loss + dice.mean() + (pe if pe is not None else 0)
        opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(params.values(), 1.0)
        opt.step()

    def infer(state):
        with torch.no_grad():
            logits, _, _, state = net.step(x[0, :1], state)
            return torch.sigmoid(logits), state

    for _ in range(args.warmup):
        train_step()
    t0 = time.perf_counter()
    for _ in range(args.iters):
        train_step()
    train_s = (time.perf_counter() - t0) / args.iters
    state = net.initial_state(1, s, s)
    for _ in range(5):
        _, state = infer(state)
    n = args.iters * 10
    t0 = time.perf_counter()
    for _ in range(n):
        _, state = infer(state)
    infer_s = (time.perf_counter() - t0) / n
    print(json.dumps({"backend": f"pytorch {torch.__version__}", "threads": args.threads,
                      "train_step_s": train_s, "infer_frame_s": infer_s}))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("reference", help="print reference outputs for the Rust tests")
    r.add_argument("--weights", required=True)
    r.add_argument("--frames", type=int, default=3)
    b = sub.add_parser("bench", help="time a training step and per-frame inference")
    b.add_argument("--weights", required=True)
    b.add_argument("--threads", type=int, default=2)
    b.add_argument("--batch", type=int, default=4)
    b.add_argument("--frames", type=int, default=10)
    b.add_argument("--iters", type=int, default=5)
    b.add_argument("--warmup", type=int, default=1)
    args = ap.parse_args()
    {"reference": cmd_reference, "bench": cmd_bench}[args.cmd](args)


if __name__ == "__main__":
    main()
