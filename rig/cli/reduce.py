"""`hopkinson reduce`: a raw shot → the two-channel record (`time_s,reference,response`).

    hopkinson reduce RAW [--grating-pitch-m D] [--orders 1,-1] [--amp-gain G]
                     [--sensitivity-v-per-m-s2 S] [--sample-rate HZ] [--bandwidth-hz B]
                     [--full-scale-v [ROLE=]RANGE ...] [--align] -o record.csv [--json]

RAW is a raw shot: an HDF5 shot file (.h5/.hdf5, rig.shotfile) or a table, CSV (header
time_s,doppler,response) or NPZ (same keys), channels in volts. With a doppler_quadrature
channel (a column, or the shot file's channel) the reference comes from the quadrature
interferometer's pair (Heydemann-corrected arctangent, analysis.reduce), else from the PM beat. Readers are looked up by the
file's suffix in RAW_READERS, so another format is one function and one entry. The options
override what a shot file records (its analysis parameters, else its configuration
snapshot); without either, the defaults of analysis.reduce apply (gain and sensitivity 1:
the response stays in volts).

Clipping is judged against the digitizer's full scale, never against the record's own
extremes: a shot file gives each channel's (its code_min/code_max, rig.shotfile
`RawShot.full_scale_v`); for a table, --full-scale-v gives it (a channel with samples there is
refused, naming it). RANGE is R (the channel reads ±R V) or LO,HI in volts; ROLE= (doppler,
doppler_quadrature, response) gives one channel's, without it every channel's; repeatable,
and over what a shot file records.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hopkinson.analysis.errors import AnalysisError
from hopkinson.rig.cli.main import emit_json


@dataclass(frozen=True)
class RawInput:
    """What a reader gives: channels in volts, timing, and the shot's own reduction settings."""

    doppler_v: Any
    response_v: Any
    sample_interval_s: float
    start_time_s: float
    settings: dict[str, Any] = field(default_factory=dict)  # keys as reduce_raw's options
    quadrature_v: Any = None  # a quadrature interferometer's second photodetector, when recorded
    full_scale_v: dict[str, tuple[float, float]] = field(default_factory=dict)  # role -> digitizer full scale, V


def _read_table(path: Path) -> RawInput:
    from hopkinson.analysis.reduce import read_raw_table

    table = read_raw_table(path)
    return RawInput(table.doppler_v, table.response_v, table.sample_interval_s, table.start_time_s,
                    quadrature_v=table.quadrature_v)


def _read_shot_file(path: Path) -> RawInput:
    from hopkinson.rig.shotfile import read_shot  # h5py: loaded only for shot files

    shot = read_shot(path)
    raw = shot.raw
    assert raw is not None
    missing = [name for name in ("doppler", "response") if name not in raw.channels]
    if missing:
        raise AnalysisError(f"{path}: the shot file has no {' or '.join(missing)} channel")
    settings: dict[str, Any] = {}
    config = shot.meta.config or {}
    analysis = config.get("analysis", {}) if isinstance(config, dict) else {}
    amplifier = config.get("amplifier", {}) if isinstance(config, dict) else {}
    for key in ("grating_pitch_m", "orders", "sensitivity_v_per_m_s2", "sample_rate_hz"):
        if key in analysis:
            settings[key] = analysis[key]
    if "gain" in amplifier:
        settings["amp_gain"] = amplifier["gain"]
    params = (shot.results or {}).get("params", {})  # what the shot's analysis actually used
    for key in ("grating_pitch_m", "orders", "amp_gain", "sensitivity_v_per_m_s2", "sample_rate_hz"):
        if params.get(key) is not None:
            settings[key] = params[key]
    quadrature = raw.volts("doppler_quadrature") if "doppler_quadrature" in raw.channels else None
    return RawInput(raw.volts("doppler"), raw.volts("response"), raw.sample_interval_s,
                    -raw.trigger_index * raw.sample_interval_s, settings, quadrature, raw.full_scale_v())


RAW_READERS: dict[str, Callable[[Path], RawInput]] = {
    ".csv": _read_table,
    ".npz": _read_table,
    ".h5": _read_shot_file,
    ".hdf5": _read_shot_file,
}


def read_raw(path: str | Path) -> RawInput:
    """Read a raw shot with the reader registered for its suffix."""
    path = Path(path)
    if not path.exists():
        raise AnalysisError(f"{path}: no such file")
    reader = RAW_READERS.get(path.suffix.lower())
    if reader is None:
        raise AnalysisError(f"{path}: unknown raw shot format '{path.suffix}' (known: {', '.join(RAW_READERS)})")
    return reader(path)


FULL_SCALE_ROLES = ("doppler", "doppler_quadrature", "response")


def parse_full_scale(texts: list[str]) -> dict[str, tuple[float, float]]:
    """--full-scale-v values ("[ROLE=]R" or "[ROLE=]LO,HI") -> role -> (low, high) volts; one
    without a role is every channel's, a role's own wins."""
    every: tuple[float, float] | None = None
    own: dict[str, tuple[float, float]] = {}
    for text in texts:
        role, _, value = text.rpartition("=")
        role = role.strip()
        if role and role not in FULL_SCALE_ROLES:
            raise AnalysisError(f"--full-scale-v: {text!r}: unknown channel {role!r} (channels: "
                                f"{', '.join(FULL_SCALE_ROLES)})")
        try:
            numbers = [float(part) for part in value.split(",")]
        except ValueError:
            numbers = []
        if len(numbers) == 1:
            numbers = [-abs(numbers[0]), abs(numbers[0])]
        if len(numbers) != 2 or not all(math.isfinite(x) and abs(x) <= 1e4 for x in numbers) \
                or not numbers[0] < numbers[1]:
            raise AnalysisError(f"--full-scale-v: {text!r}: expected R (±R V) or LO,HI in volts, finite, LO < HI "
                                "(at most 10 kV), optionally after ROLE=")
        if role:
            own[role] = (numbers[0], numbers[1])
        else:
            every = (numbers[0], numbers[1])
    return {**({role: every for role in FULL_SCALE_ROLES} if every is not None else {}), **own}


def parse_orders(text: str) -> tuple[int, int]:
    """'1,-1' → (1, -1); one clear message otherwise."""
    parts = [p.strip() for p in str(text).split(",")]
    try:
        if len(parts) != 2:
            raise ValueError
        orders = (int(parts[0]), int(parts[1]))
    except ValueError:
        raise AnalysisError(f"--orders: expected two diffraction orders like 1,-1, got {text!r}") from None
    if orders[0] == orders[1]:
        raise AnalysisError(f"--orders: the two diffraction orders must differ, got {text!r}")
    return orders


# The command's flags by AnalysisOptions option, so a bad value is named as it was typed.
FLAGS = {"grating_pitch_m": "--grating-pitch-m", "amp_gain": "--amp-gain",
         "sensitivity_v_per_m_s2": "--sensitivity-v-per-m-s2", "sample_rate_hz": "--sample-rate"}


def _check_numbers(args: argparse.Namespace) -> None:
    """Every numeric option finite and sensible (AnalysisOptions.check), named by its flag."""
    from hopkinson.analysis.options import AnalysisOptions

    values = {key: getattr(args, flag[2:].replace("-", "_")) for key, flag in FLAGS.items()}
    values = {k: v for k, v in values.items() if v is not None}
    try:
        AnalysisOptions.from_options(**values)
    except AnalysisError as exc:
        from hopkinson.rig.cli.identify import named_by_flag

        raise named_by_flag(exc, FLAGS) from None
    if args.bandwidth_hz is not None and not (math.isfinite(args.bandwidth_hz) and 0 < args.bandwidth_hz <= 1e10):
        raise AnalysisError(f"--bandwidth-hz: a finite number of Hz above 0 (at most 1e10), got {args.bandwidth_hz!r}")


def run_reduce(args: argparse.Namespace) -> int:
    """Reduce RAW, write the record (never over RAW or a shot file; atomically), print the
    shock quantities."""
    from hopkinson.analysis.records import write_record
    from hopkinson.analysis.reduce import DEFAULT_GRATING_PITCH_M, interferometer_text, reduce_raw
    from hopkinson.analysis.resample import DEFAULT_ANALYSIS_RATE_HZ
    from hopkinson.fileio import check_output_path

    _check_numbers(args)
    full_scale_v = parse_full_scale(args.full_scale_v)
    check_output_path(args.output, [args.raw], what="record")
    raw = read_raw(args.raw)
    settings = dict(raw.settings)
    for key, value in (("grating_pitch_m", args.grating_pitch_m), ("amp_gain", args.amp_gain),
                       ("sensitivity_v_per_m_s2", args.sensitivity_v_per_m_s2),
                       ("sample_rate_hz", args.sample_rate)):
        if value is not None:
            settings[key] = value
    if args.orders is not None:
        settings["orders"] = args.orders
    orders = settings.get("orders", "1,-1")
    orders = parse_orders(orders if isinstance(orders, str) else ",".join(str(o) for o in orders))
    reduction = reduce_raw(
        raw.doppler_v, raw.response_v, raw.sample_interval_s, quadrature_v=raw.quadrature_v,
        grating_pitch_m=float(settings.get("grating_pitch_m", DEFAULT_GRATING_PITCH_M)),
        orders=orders,
        amp_gain=float(settings.get("amp_gain", 1.0)),
        sensitivity_v_per_m_s2=float(settings.get("sensitivity_v_per_m_s2", 1.0)),
        sample_rate_hz=float(settings.get("sample_rate_hz", DEFAULT_ANALYSIS_RATE_HZ)),
        bandwidth_hz=args.bandwidth_hz,
        align=args.align,
        start_time_s=raw.start_time_s,
        source=str(args.raw),
        full_scale_v={**raw.full_scale_v, **full_scale_v},
    )
    reduction.check_direction_known(str(args.raw))
    out = write_record(args.output, reduction.record)
    result = {"raw": str(args.raw), "output": str(out), "samples": reduction.record.n_samples,
              **reduction.quantities()}
    if args.json:
        emit_json(result)
    else:
        print(f"{out}: {reduction.record.n_samples} samples at {reduction.record.sample_rate_hz / 1e6:g} MS/s")
        print(f"  interferometer     {interferometer_text(result)}")
        print(f"  peak acceleration  {result['peak_acceleration_m_s2']:.6g} m/s^2")
        print(f"  pulse width (10 %) {result['pulse_width_s'] * 1e6:.4g} us")
        print(f"  peak velocity      {result['peak_velocity_m_s']:.6g} m/s")
        print(f"  shock sensitivity  {result['shock_sensitivity']:.6g} ({result['response_unit']} per m/s^2)")
        print(f"  delay              {result['delay_s'] * 1e6:.4g} us{' (removed)' if args.align else ''}")
        print(f"  bandwidth          {result['demodulation_bandwidth_hz'] / 1e3:.4g} kHz")
    return 0


def register(subparsers: Any) -> None:
    """Add the `reduce` sub-command."""
    p = subparsers.add_parser(
        "reduce",
        help="reduce a raw shot (PM Doppler beat or quadrature pair + amplifier volts) to a two-channel record",
        description="Demodulate the photomultiplier beat of the Doppler interferometer (or a quadrature "
        "interferometer's pair, doppler + doppler_quadrature) into the reference acceleration, scale the "
        "amplifier output to m/s^2, bring both to the analysis rate and write the record "
        "time_s,reference,response. RAW: .h5 shot file, or .csv/.npz with time_s,doppler,response "
        "(and optionally doppler_quadrature).",
    )
    p.add_argument("raw", metavar="RAW", help="raw shot (.h5/.hdf5 shot file, .csv or .npz)")
    p.add_argument("--grating-pitch-m", type=float, metavar="D", help="grating pitch d in m (default 2e-6)")
    p.add_argument("--orders", metavar="PHI,XI", help="diffraction orders (default 1,-1)")
    p.add_argument("--amp-gain", type=float, metavar="G", help="bridge amplifier gain (default 1)")
    p.add_argument("--sensitivity-v-per-m-s2", type=float, metavar="S",
                   help="accelerometer nominal sensitivity at the amplifier input, V per m/s^2 (default 1: "
                   "with gain 1 the response stays in volts)")
    p.add_argument("--sample-rate", type=float, metavar="HZ", help="analysis rate in Hz (default 1e6)")
    p.add_argument("--bandwidth-hz", type=float, metavar="B",
                   help="bandwidth of the differentiating low-pass (default: chosen from the pulse)")
    p.add_argument("--full-scale-v", action="append", default=[], metavar="[ROLE=]RANGE",
                   help="the digitizer's full scale, to judge clipping against: R (±R V) or LO,HI volts, for "
                        "every channel or ROLE= doppler, doppler_quadrature, response (repeatable; a shot file "
                        "records its own)")
    p.add_argument("--align", action="store_true",
                   help="shift the response by the estimated delay (default: report it only)")
    p.add_argument("-o", "--output", required=True, metavar="RECORD", help="output record (.csv or .npz)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run_reduce)
