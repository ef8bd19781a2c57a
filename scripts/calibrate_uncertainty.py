#!/usr/bin/env python3
"""Calibrates the articulated fit's uncertainty for one source of masks.

The fit reports, per frame, the radius (`Calibration::radius` in perception/src/pose)

    max(scale * sigma + floor, spread)

sigma: the curvature of its score, mapped to metres at the forearm's centre and wrist;
spread: how far apart the hypotheses the masks cannot tell apart put them; floor: one per
band of the share of the forearm's region that the depth image shows hidden by something in
front of the arm (`hidden_share`; bands from 0, 25, 50 and 75 %, `HIDDEN_BANDS`), each band's
floor at least the band before's. This script reads the per-frame CSV of

    workcell eval pose --split validation [--masks procnet] [--depth] --out DIR

(its `sigma_m`, `spread_m`, `hidden_share` and `ends_cm` columns: the error to cover is the
farther of the forearm's centre and wrist) and, for each scale on a grid, finds the smallest
floors that put the coverage target of each band's frames within the radius. It prints the
table and the calibration with the smallest mean radius; given a second CSV (the test split)
it reports the coverage there too, which is the honest figure: the calibration was chosen on
the first.

    scripts/calibrate_uncertainty.py VALIDATION.csv [TEST.csv] [--target 0.99]
        [--pool VALIDATION2.csv TEST2.csv]... [--tracked-floors] [--confident-gain G]
        [--confident-bands N]
        [--write WEIGHTS --depth|--no-depth]

`--write WEIGHTS` puts the chosen calibration into the calibration file beside the weights
(`procnet-cpu.safetensors` has `procnet-cpu.calibration.toml`), with the weights' SHA-256,
as the section of a fit with (`--depth`) or without (`--no-depth`) the depth image; the
other section of an existing file of the same weights is kept. workcell applies a
calibration to the weights of its hash only (`Calibration::of_weights`).

`--tracked-floors` gives the fits that kept their track (the CSV's `reacquired` false: the
tracked hypotheses explained the masks well enough that the global search did not run) floors
of their own, each band for the target of its own frames, and the re-acquired fits theirs:
a fit that kept its track is rarely far off, and one floor for both is set by the re-acquired.

`--confident-gain G` gives the fits whose gain is at least G floors of their own (each band
for the target of its own frames), before any other floors: a fit that explains the masks
that well is rarely far off, on recorded people as on the generator's motion, and one floor
for every fit is set by the poor ones. `--confident-bands N` keeps those floors to the first
N bands of the hidden share (no band, then from 25, 50, 75 %): in the bands from the N-th on
a fit of that gain takes the floor any fit of the band takes, where that is larger (with
three quarters of the forearm hidden, the gain reads a quarter of it). Where the CSVs have
the `recorded` column, the coverage of recorded people's frames and of the generator's is
reported apart: a bound fitted on a mix can hold for one and not the other.

`--write` also records the fit's settings the CSVs were measured with (`fit.toml`, which
`workcell eval pose` writes beside `pose_frames.csv`) as the section's `fit` table, so that
workcell runs the fit whose bound this is (`Calibration::apply`); CSVs of different fits are
refused.

`--pool` adds a second source of the same masks' frames (the tracker's own crops beside the
stored ones, say): the calibration is chosen on every validation CSV together, and each
source's coverage is reported on its own, so that a bound that holds on one kind of frame
and not the other shows.

Standard library only.
"""

import argparse
import csv
import hashlib
import math
import os
import statistics
import sys
import tomllib

SCALES = [0.0, 0.5, 1.0, 2.0, 3.0, 5.0, 8.0, 10.0, 15.0, 20.0]
# Where each band of the hidden share starts after the first (perception's HIDDEN_BANDS).
HIDDEN_BANDS = [0.25, 0.5, 0.75]


def hidden_of(row):
    """The row's hidden share: 0 where the CSV has none (no depth, or an older CSV)."""
    try:
        h = float(row.get("hidden_share") or 0.0)
    except ValueError:
        return 0.0
    return h if h == h else 0.0


def load(path, min_gain=None):
    """(error m, sigma m, spread m, hidden share, kept its track, gain, recorded person) of
    every frame with a pose (and, given `min_gain`, a gain of at least that); recorded is
    None where the CSV does not say."""
    try:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
    except OSError as e:
        sys.exit(f"{path}: {e}")
    missing = {"no_pose", "ends_cm", "sigma_m", "spread_m"} - set(rows[0] if rows else {})
    if missing:
        sys.exit(
            f"{path}: not a pose_frames.csv of `workcell eval pose --method articulated` "
            f"(no {sorted(missing)})"
        )
    return [
        (
            float(r["ends_cm"]) / 100.0,
            float(r["sigma_m"]),
            float(r["spread_m"]),
            hidden_of(r),
            r.get("reacquired") == "false",
            float(r.get("gain") or 0.0),
            {"true": True, "false": False}.get(r.get("recorded")),
        )
        for r in rows
        if r["no_pose"] == "" and r["ends_cm"] != ""
        and (min_gain is None or float(r["gain"]) >= min_gain)
    ]


def quantile(sorted_values, q):
    return sorted_values[min(len(sorted_values) - 1, int(q * len(sorted_values)))]


def band(hidden):
    """The band of a hidden share: 0 below the first of HIDDEN_BANDS, then 1, 2, 3."""
    return sum(1 for b in HIDDEN_BANDS if hidden >= b)


def band_of(frame):
    """The band of a frame (error, sigma, spread[, hidden]); no hidden share is band 0."""
    return band(frame[3] if len(frame) > 3 else 0.0)


def tracked(frame):
    """Whether `frame` (error, sigma, spread[, hidden[, kept its track]]) kept its track."""
    return len(frame) > 4 and frame[4]


def gain_of(frame):
    """The gain of `frame` (error, sigma, spread, hidden, kept its track, gain[, ...]); 0
    where it has none."""
    return frame[5] if len(frame) > 5 else 0.0


def recorded_of(frame):
    """Whether `frame` is of a recorded person: True, False, or None where not known."""
    return frame[6] if len(frame) > 6 else None


def confident_of(calibration):
    """(gain, floors: no band, then each band) of the confident fits under `calibration`
    (scale, floor, hidden floors, tracked floors, confident), or None: the gain chooses no
    floors."""
    return calibration[4] if len(calibration) > 4 else None


def tracked_floors_of(calibration):
    """The floors (no band, then each band) of fits that kept their track under
    `calibration` (scale, floor[, hidden floors[, tracked floors]]), or None: the same as
    any fit's."""
    return calibration[3] if len(calibration) > 3 else None


def floor_at(calibration, frame):
    """The floor for `frame` under `calibration` (scale, floor[, hidden floors[, tracked
    floors[, confident]]]): its band's, never below a less hidden band's; the confident
    floors' for a frame of their gain or more, else the tracked floors' for a frame that kept
    its track, where the calibration has them (Calibration::radius)."""
    own = tracked_floors_of(calibration)
    confident = confident_of(calibration)
    if confident is not None and gain_of(frame) >= confident[0]:
        floors = list(confident[1])
    elif own is not None and tracked(frame):
        floors = list(own)
    else:
        floors = [calibration[1]] + list(calibration[2] if len(calibration) > 2 else [])
    return max(floors[: band_of(frame) + 1])


def radius(frame, calibration):
    """The radius the fit reports for `frame` (error, sigma, spread[, hidden]) under
    `calibration` (scale, floor[, hidden floors])."""
    return max(calibration[0] * frame[1] + floor_at(calibration, frame), frame[2])


def smallest_floor(frames, scale, target):
    """The smallest floor with `target` of `frames` within max(scale sigma + floor, spread)."""
    if not frames:
        return 0.0
    # A frame is covered by its spread alone, or needs error - scale * sigma of floor.
    need = sorted(0.0 if f[0] <= f[2] else f[0] - scale * f[1] for f in frames)
    return max(0.0, quantile(need, target))


def band_floors(frames, scale, target):
    """(scale, floor, hidden floors): each band's smallest floor for `target` of its own
    frames, at least the band before's (a band without frames takes the band before's)."""
    floors = []
    for b in range(len(HIDDEN_BANDS) + 1):
        own = [f for f in frames if band_of(f) == b]
        floors.append(max([smallest_floor(own, scale, target)] + floors[-1:]))
    return (scale, floors[0], tuple(floors[1:]))


def split_floors(frames, scale, target):
    """(scale, floor, hidden floors, tracked floors): band_floors of the re-acquired frames,
    and of the frames that kept their track as the tracked floors (no band, then each)."""
    _, floor, hidden = band_floors([f for f in frames if not tracked(f)], scale, target)
    _, t_floor, t_hidden = band_floors([f for f in frames if tracked(f)], scale, target)
    return (scale, floor, hidden, (t_floor,) + tuple(t_hidden))


def coverage(frames, calibration):
    return sum(1 for f in frames if f[0] <= radius(f, calibration)) / len(frames)


def calibrate(frames, target, tracked_floors=False, confident_gain=None, confident_bands=None):
    """Per scale, (scale, floor, hidden floors[, tracked floors[, confident]]) and its mean
    radius; and the row of smallest mean radius. With `tracked_floors`, the frames that kept
    their track and the re-acquired ones each get floors for `target` of their own; with
    `confident_gain`, the frames of that gain or more get floors of their own first
    (confident: (gain, floors)), and the others are calibrated as before; with
    `confident_bands` N, the confident floors of the bands from the N-th on are at least the
    others' of the band."""
    rows = []
    sure = [] if confident_gain is None else [f for f in frames if gain_of(f) >= confident_gain]
    if confident_gain is not None and not sure:
        sys.exit(f"no frame with a pose has a gain of {confident_gain:g} or more")
    rest = [f for f in frames if confident_gain is None or gain_of(f) < confident_gain]
    for a in SCALES:
        if tracked_floors:
            calibration = split_floors(rest, a, target)
        else:
            calibration = band_floors(rest, a, target)
        if confident_gain is not None:
            calibration = calibration[:3] + (tracked_floors_of(calibration),)
            _, floor, hidden = band_floors(sure, a, target)
            floors = [floor] + list(hidden)
            if confident_bands is not None:
                anyone = [calibration[1]] + list(calibration[2])
                for b in range(confident_bands, len(floors)):
                    floors[b] = max(floors[b], anyone[b])
            calibration = calibration + ((confident_gain, tuple(floors)),)
        rows.append((calibration, statistics.mean(radius(f, calibration) for f in frames)))
    return rows, min(rows, key=lambda r: r[1])


def calibration_path(weights):
    """The calibration file beside `weights`: the extension replaced (as workcell does)."""
    return os.path.splitext(weights)[0] + ".calibration.toml"


def toml_float(x):
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return repr(float(x))


def toml_value(v):
    """A fit setting as TOML: a boolean, an integer or a float."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    return toml_float(v)


FIT_KEYS = {"fit_trunk", "search_below_gain", "reversed_start", "depth_start"}
# Settings that runs before them do not write (the fit then ran as their defaults say).
OPTIONAL_FIT_KEYS = {"hull_outlines", "hand_region", "trunk_downsample"}


def fit_settings(csv_path):
    """The fit's settings (FitSettings) that `workcell eval pose` wrote beside `csv_path`
    (`fit.toml` for `pose_frames.csv`, `fit_SUFFIX.toml` for `pose_frames_SUFFIX.csv`), or
    None where there is none (an older run)."""
    folder, name = os.path.split(csv_path)
    suffix = name[len("pose_frames"):-len(".csv")] if name.startswith("pose_frames") else ""
    path = os.path.join(folder, f"fit{suffix}.toml")
    if not os.path.isfile(path):
        return None
    try:
        with open(path, "rb") as f:
            doc = tomllib.load(f)
    except (OSError, tomllib.TOMLDecodeError) as e:
        sys.exit(f"{path}: {e}")
    if not FIT_KEYS <= set(doc) <= FIT_KEYS | OPTIONAL_FIT_KEYS:
        sys.exit(
            f"{path}: not the fit's settings (keys {sorted(doc)}, expected "
            f"{sorted(FIT_KEYS)} and any of {sorted(OPTIONAL_FIT_KEYS)})"
        )
    return doc


def write_calibration(weights, section, calibration, fitted_on, confirm_min_gain=math.inf,
                      confirmed_floor_m=0.0, min_gain=None, fit=None):
    """Writes `calibration` ((scale, floor, hidden floors[, tracked floors])) as `section`
    (`with_depth` or `without_depth`) of the calibration file beside `weights`, with the fit's
    settings `fit` (a dict of FitSettings' keys) where given; returns its path."""
    with open(weights, "rb") as f:
        sha = hashlib.sha256(f.read()).hexdigest()
    path = calibration_path(weights)
    doc = {}
    if os.path.exists(path):
        with open(path, "rb") as f:
            doc = tomllib.load(f)
        if doc.get("weights_sha256") != sha:
            sys.exit(
                f"{path} holds the calibration of other weights "
                f"({doc.get('weights_sha256')}, these are {sha}): remove it first"
            )
    scale, floor, hidden = calibration[:3]
    doc[section] = {
        "scale": scale,
        "floor_m": floor,
        "hidden_floors_m": list(hidden),
        "confirm_min_gain": confirm_min_gain,
        "confirmed_floor_m": confirmed_floor_m,
    }
    if min_gain is not None:
        doc[section]["min_gain"] = min_gain
    if tracked_floors_of(calibration) is not None:
        doc[section]["tracked_floors_m"] = list(tracked_floors_of(calibration))
    if confident_of(calibration) is not None:
        gain, floors = confident_of(calibration)
        doc[section]["confident"] = {"min_gain": gain, "floors_m": list(floors)}
    if fit is not None:
        doc[section]["fit"] = dict(fit)
    lines = [
        f"# The pose bound's calibration for {os.path.basename(weights)}: "
        "scripts/calibrate_uncertainty.py --write.",
        f'weights_sha256 = "{sha}"',
        "fitted_on = " + '"' + fitted_on.replace("\\", "\\\\").replace('"', '\\"') + '"',
    ]
    for name in ("with_depth", "without_depth"):
        if name in doc:
            c = doc[name]
            lines += [
                "",
                f"[{name}]",
                f"scale = {toml_float(c['scale'])}",
                f"floor_m = {toml_float(c['floor_m'])}",
                "hidden_floors_m = [" + ", ".join(toml_float(h) for h in c["hidden_floors_m"]) + "]",
                f"confirm_min_gain = {toml_float(c['confirm_min_gain'])}",
                f"confirmed_floor_m = {toml_float(c['confirmed_floor_m'])}",
            ]
            if "min_gain" in c:
                lines.append(f"min_gain = {toml_float(c['min_gain'])}")
            if "tracked_floors_m" in c:
                lines.append(
                    "tracked_floors_m = ["
                    + ", ".join(toml_float(h) for h in c["tracked_floors_m"]) + "]"
                )
            if "confident" in c:
                lines += [
                    "",
                    f"[{name}.confident]",
                    f"min_gain = {toml_float(c['confident']['min_gain'])}",
                    "floors_m = ["
                    + ", ".join(toml_float(h) for h in c["confident"]["floors_m"]) + "]",
                ]
            if "fit" in c:
                lines += ["", f"[{name}.fit]"] + [
                    f"{k} = {toml_value(v)}" for k, v in c["fit"].items()
                ]
    with open(path + ".tmp", "w") as f:
        f.write("\n".join(lines) + "\n")
    os.replace(path + ".tmp", path)
    return path


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("validation")
    parser.add_argument("test", nargs="?")
    parser.add_argument("--target", type=float, default=0.99)
    parser.add_argument(
        "--pool",
        nargs=2,
        action="append",
        default=[],
        metavar=("VALIDATION", "TEST"),
        help="another source's CSVs, pooled into the calibration, reported on their own",
    )
    parser.add_argument("--tracked-floors", action="store_true",
                        help="floors of their own for the fits that kept their track")
    parser.add_argument("--confident-gain", type=float, default=None, metavar="G",
                        help="floors of their own for the fits of gain G or more")
    parser.add_argument("--confident-bands", type=int, default=None, metavar="N",
                        help="with --confident-gain: their own floors in the first N bands "
                             "of the hidden share only (1 to 4)")
    parser.add_argument("--write", metavar="WEIGHTS", help="write the calibration beside WEIGHTS")
    depth = parser.add_mutually_exclusive_group()
    depth.add_argument("--depth", dest="depth", action="store_true", default=None,
                       help="with --write: the calibration of a fit that reads depth")
    depth.add_argument("--no-depth", dest="depth", action="store_false",
                       help="with --write: the calibration of a fit of the masks alone")
    parser.add_argument("--confirm-min-gain", type=float, default=math.inf,
                        help="with --write: the gain from which a confirmed fit is a pose")
    parser.add_argument("--confirmed-floor-m", type=float, default=0.0,
                        help="with --write: the least bound of a confirmed pose, m")
    parser.add_argument("--min-gain", type=float, default=None,
                        help="the fit's gain threshold the bound is for: frames below it "
                        "count as no pose, and --write writes it (make the CSVs with "
                        "`eval pose --min-gain` too: a frame turned down changes the track)")
    args = parser.parse_args()
    if args.write and args.depth is None:
        sys.exit("--write needs --depth or --no-depth: which fit the calibration is for")
    if not 0.0 < args.target < 1.0:
        sys.exit("--target is a fraction in (0, 1)")
    if args.pool and not args.test:
        sys.exit("--pool needs the first source's TEST.csv too")
    sources = [(args.validation, args.test)] + [tuple(p) for p in args.pool]
    if args.min_gain is not None and not 0.0 <= args.min_gain <= 1.0:
        sys.exit("--min-gain is a gain from 0 to 1")
    loaded = [
        (load(v, args.min_gain), load(t, args.min_gain) if t else None) for v, t in sources
    ]
    for (v_path, _), (v, _) in zip(sources, loaded):
        if not v:
            sys.exit(f"{v_path}: no frame with a pose")
    val = [f for v, _ in loaded for f in v]
    test = [f for _, t in loaded if t for f in t] if args.test else None
    errors = sorted(f[0] for f in val)
    print(
        f"{' + '.join(v for v, _ in sources)}: {len(val)} frames with a pose; error median "
        f"{100 * quantile(errors, 0.5):.2f} cm, 99th percentile {100 * quantile(errors, 0.99):.2f} cm"
    )
    fits = {p: fit_settings(p) for v, t in sources for p in (v, t) if p}
    if len({repr(sorted(f.items())) if f else None for f in fits.values()}) > 1:
        sys.exit(
            "the CSVs were measured with different fits: "
            + "; ".join(f"{p}: {f}" for p, f in fits.items())
        )
    fit = next(iter(fits.values()))
    if args.tracked_floors:
        for name, frames in (("validation", val), ("test", test or [])):
            kept = sum(1 for f in frames if tracked(f))
            if frames:
                print(f"{name}: {kept} of {len(frames)} frames with a pose kept their track")
    if args.confident_gain is not None and not 0.0 <= args.confident_gain <= 1.0:
        sys.exit("--confident-gain is a gain from 0 to 1")
    if args.confident_bands is not None and (
        args.confident_gain is None or not 1 <= args.confident_bands <= len(HIDDEN_BANDS) + 1
    ):
        sys.exit(f"--confident-bands is 1 to {len(HIDDEN_BANDS) + 1}, with --confident-gain")
    rows, best = calibrate(
        val, args.target, args.tracked_floors, args.confident_gain, args.confident_bands
    )
    print(
        "| scale | floor (cm) | floors hidden 25/50/75 % (cm) | mean radius (cm) "
        "| 95th pct radius (cm) | validation coverage |" + (" test coverage |" if test else "")
    )
    print("|---|---|---|---|---|---|" + ("---|" if test else ""))
    for calibration, mean in rows:
        a, floor, hidden = calibration[:3]
        radii = sorted(radius(f, calibration) for f in val)
        row = (
            f"| {a:g} | {100 * floor:.2f} | {' / '.join(f'{100 * h:.2f}' for h in hidden)} "
            f"| {100 * mean:.2f} | {100 * quantile(radii, 0.95):.2f} "
            f"| {100 * coverage(val, calibration):.2f} % |"
        )
        if test:
            row += f" {100 * coverage(test, calibration):.2f} % of {len(test)} |"
        print(row)
    (a, floor, hidden), mean = best[0][:3], best[1]
    print(
        f"\nsmallest mean radius: scale {a:g}, floor {floor:.4f} m, hidden floors "
        f"{', '.join(f'{h:.4f}' for h in hidden)} m (mean {100 * mean:.2f} cm)"
    )
    if tracked_floors_of(best[0]) is not None:
        print(
            "  fits that kept their track: floors "
            + ", ".join(f"{h:.4f}" for h in tracked_floors_of(best[0])) + " m"
        )
        for name, frames in (("validation", val), ("test", test or [])):
            for kept, label in ((True, "kept their track"), (False, "re-acquired")):
                own = [f for f in frames if tracked(f) == kept]
                if own:
                    print(f"  {name}, {label}: {100 * coverage(own, best[0]):.2f} % of {len(own)}")
    if confident_of(best[0]) is not None:
        gain, floors = confident_of(best[0])
        print(
            f"  fits of gain {gain:g} or more: floors " + ", ".join(f"{h:.4f}" for h in floors) + " m"
        )
        for name, frames in (("validation", val), ("test", test or [])):
            for sure, label in ((True, f"gain {gain:g} or more"), (False, f"gain below {gain:g}")):
                own = [f for f in frames if (gain_of(f) >= gain) == sure]
                if own:
                    print(f"  {name}, {label}: {100 * coverage(own, best[0]):.2f} % of {len(own)}")
    for name, frames in (("validation", val), ("test", test or [])):
        for who, label in ((True, "recorded people"), (False, "the generator's motion")):
            own = [f for f in frames if recorded_of(f) is who]
            if own and len(own) < len(frames):
                mean = statistics.mean(radius(f, best[0]) for f in own)
                print(
                    f"{name}, {label}: {100 * coverage(own, best[0]):.2f} % of {len(own)} "
                    f"within, mean radius {100 * mean:.2f} cm"
                )
    print("\ncoverage per band of the hidden share (validation" + (", test)" if test else ")"))
    for b in range(len(HIDDEN_BANDS) + 1):
        cells = []
        for frames in [val] + ([test] if test else []):
            own = [f for f in frames if band_of(f) == b]
            cells.append(
                f"{100 * coverage(own, best[0]):.2f} % of {len(own)}" if own else "no frames"
            )
        print(f"  from {100 * ([0.0] + HIDDEN_BANDS)[b]:.0f} %: " + "; ".join(cells))
    if args.write:
        fitted_on = f"{len(val)} frames of {', '.join(v for v, _ in sources)}, target {args.target}"
        if test:
            fitted_on += f"; {100 * coverage(test, best[0]):.2f} % of {len(test)} test frames within"
        path = write_calibration(
            args.write,
            "with_depth" if args.depth else "without_depth",
            best[0],
            fitted_on,
            args.confirm_min_gain,
            args.confirmed_floor_m,
            args.min_gain,
            fit,
        )
        print(f"\nwrote {path}")
    if len(sources) > 1:
        print("\ncoverage per source (validation, test)")
        for (v_path, t_path), (v, t) in zip(sources, loaded):
            print(
                f"  {v_path}: {100 * coverage(v, best[0]):.2f} % of {len(v)}; "
                f"{t_path}: {100 * coverage(t, best[0]):.2f} % of {len(t)}"
            )


if __name__ == "__main__":
    main()
