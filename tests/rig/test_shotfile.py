"""Shot files: exact round-trips, atomic writes under a real crash, clear errors for bad files."""

from __future__ import annotations

import hashlib
import json
import math
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import h5py
import numpy as np
import pytest

from hopkinson.analysis.records import Record
from hopkinson.rig.run_folder import RunFolder
from hopkinson.rig.shotfile import (
    RawChannel,
    RawShot,
    ShotFileError,
    ShotMeta,
    read_shot,
    read_shot_meta,
    software_version,
)
from hopkinson.rig.shotfile_writer import add_analysis, write_raw_shot

N = 5000
TRIGGER = 1200


def known_raw(n: int = N) -> RawShot:
    rng = np.random.default_rng(7)
    doppler = rng.integers(-32768, 32768, n, dtype=np.int16)
    doppler[:2] = (-32768, 32767)  # the extremes survive
    response = (np.arange(n) % 2000 - 1000).astype(np.int16)
    return RawShot(
        {"doppler": (doppler, 3.0517578125e-05, -0.0125), "response": RawChannel(response, 1.25e-4, 0.5)},
        sample_interval_s=1e-8,
        trigger_index=TRIGGER if n > TRIGGER else n // 4,
    )


def known_meta(**changes: object) -> ShotMeta:
    fields = dict(
        operator="A. Technician",
        accelerometer_model="AYZ-3",
        accelerometer_serial="SN0001",
        pressure_bar=2.5,
        projectile=3,
        instruments={"digitizer": "SIM,DIGITIZER,0001,1.0", "amplifier": "SIM-AMP 2.1"},
        config={
            "digitizer": {"sample_rate_hz": 1.0e8, "record_length": N, "resource": "TCPIP0::127.0.0.1::5025::SOCKET"},
            "limits": {"max_pressure_bar": 6.0},
            "analysis": {"orders": [1, -1], "grating_pitch_m": 1.0e-6},
        },
        shot_id="s001-r1",
        shot_index=0,
        campaign_id="demo-20260101T000000Z",
        simulated_truth={"poles": [[0.9740, 0.1396], [0.9740, -0.1396]], "natural_frequency_hz": 30000.0},
    )
    fields.update(changes)
    return ShotMeta(**fields)  # type: ignore[arg-type]


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_raw_round_trip_and_layout(tmp_path: Path) -> None:
    raw, meta = known_raw(), known_meta()
    path = write_raw_shot(tmp_path / "s001-r1.h5", raw, meta)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s001-r1.h5"]  # no tmp left behind

    shot = read_shot(path)
    assert shot.state == "raw" and shot.results is None and shot.record is None
    assert shot.meta == meta
    assert shot.meta.software_version == software_version() != "unknown"
    assert shot.raw is not None and shot.raw.sample_interval_s == 1e-8 and shot.raw.trigger_index == TRIGGER
    for name in ("doppler", "response"):
        codes, scale_v, offset_v, *_ = raw.channels[name]
        got = shot.raw.channels[name]
        assert got.codes.dtype == np.int16 and np.array_equal(got.codes, codes)
        assert (got.scale_v, got.offset_v) == (scale_v, offset_v)
        # volts = codes * scale + offset, computed here independently of the module
        assert np.array_equal(shot.volts(name), codes.astype(float) * scale_v + offset_v)
    assert shot.volts("doppler")[1] == 32767 * 3.0517578125e-05 - 0.0125
    assert shot.raw.time_s[TRIGGER] == 0.0 and shot.raw.time_s[0] == pytest.approx(-TRIGGER * 1e-8)

    # The layout docs/files-and-formats.md promises, readable without this module.
    with h5py.File(path, "r") as f:
        ds = f["raw/doppler"]
        assert ds.dtype == np.int16 and ds.fletcher32
        assert ds.attrs["scale_v"] == 3.0517578125e-05 and ds.attrs["offset_v"] == -0.0125
        assert ds.attrs["sample_interval_s"] == 1e-8 and ds.attrs["trigger_index"] == TRIGGER
        assert f.attrs["uuid"] == meta.uuid and f.attrs["utc_time"] == meta.utc_time
        assert f.attrs["accelerometer_serial"] == "SN0001" and f.attrs["simulated"]
        assert json.loads(f.attrs["config_json"]) == meta.config
        assert f["meta/config/digitizer"].attrs["sample_rate_hz"] == 1.0e8
        assert list(f["meta/config/analysis/orders"][...]) == [1, -1]
        assert f["meta/instruments"].attrs["digitizer"] == "SIM,DIGITIZER,0001,1.0"
        assert f["truth/poles"].shape == (2, 2)
    assert read_shot_meta(path) == meta
    assert read_shot(path, load_raw=False).raw is None


def test_meta_defaults_fill_uuid_time_and_version(tmp_path: Path) -> None:
    meta = ShotMeta("op", "M", "S", 1.0, 3)
    shot = read_shot(write_raw_shot(tmp_path / "a.h5", known_raw(64), meta))
    assert shot.meta.uuid == meta.uuid and len(meta.uuid) == 36
    assert shot.meta.utc_time.endswith("Z") and shot.meta.simulated_truth is None
    assert shot.meta.shot_id is None and shot.meta.config == {}
    assert ShotMeta("op", "M", "S", 1.0, 3).uuid != meta.uuid



def test_a_further_sensors_identity_round_trips_and_a_damaged_one_is_one_clear_error(tmp_path: Path) -> None:
    second = {"response_2": {"model": "AYZ-3", "serial": "SN0002"}}
    path = write_raw_shot(tmp_path / "a.h5", known_raw(64), known_meta(sensor_identities=second))
    assert read_shot(path).meta.sensor_identities == second == read_shot_meta(path).sensor_identities
    assert read_shot(write_raw_shot(tmp_path / "b.h5", known_raw(64), known_meta())).meta.sensor_identities == {}
    with h5py.File(path, "r+") as f:
        f.attrs["sensors_json"] = '{"response_2": ["AYZ-3", 7]}'
    for reader in (read_shot, read_shot_meta):
        with pytest.raises(ShotFileError, match=r"a\.h5: damaged shot file: meta cannot be read"):
            reader(path)

RESULTS = {
    "model": {
        "sample_interval_s": 1e-6,
        "order": 4,
        "a": [1.0, -3.5828, 4.9151, -3.0575, 0.7261],
        "b": [0.0, 0.1 + 0.2, 1e-300, -2.5e-17, 0.0],
        "poles": [[0.9740, 0.1396], [0.9740, -0.1396], [0.8174, 0.0518], [0.8174, -0.0518]],
        "loss_by_order": [1.0, 0.5, 0.2, 0.01, 0.0099],
    },
    "fbsd_hz": {"5": 7200.0, "10": 9600.0},
    "pole_analysis": [{"pole": [0.974, 0.1396], "response_time_samples": 185.45, "ratio": 1.0}],
    "dcm": {"ratio": 12.5, "damping": 0.707, "compensated_fbsd_hz": {"5": 62200.0, "10": 78400.0}},
    "excitation": {"pulse_width_s": 3.86e-05, "band_hz": None, "warnings": ["pulse close to the rule"]},
    "shock": {"peak_acceleration_m_s2": 9.80665e5, "fit_percent": float("nan")},
}


def test_analysis_round_trip_exact(tmp_path: Path) -> None:
    raw = known_raw()
    path = write_raw_shot(tmp_path / "s.h5", raw, known_meta())
    time_s = np.arange(300) * 1e-6
    record = Record(1e-6, np.sin(time_s * 1e4) * 1e6, np.cos(time_s * 1e4), start_time_s=-5e-5)
    velocity = np.linspace(0.0, 12.5, 300)
    add_analysis(path, RESULTS, record=record, derived={"velocity_m_s": velocity})

    shot = read_shot(path)
    assert shot.state == "analysed" and shot.analysis_error is None
    # Exact round trip: same JSON text (NaN compares unequal to itself, JSON text does not).
    assert json.dumps(shot.results) == json.dumps(RESULTS)
    assert shot.results["model"]["b"][1] == 0.1 + 0.2 and math.isnan(shot.results["shock"]["fit_percent"])
    assert shot.record is not None
    assert np.array_equal(shot.record.reference, record.reference)
    assert np.array_equal(shot.record.response, record.response)
    assert (shot.record.sample_interval_s, shot.record.start_time_s) == (1e-6, -5e-5)
    assert np.array_equal(shot.derived["velocity_m_s"], velocity)
    for name in ("doppler", "response"):  # raw data untouched by the rewrite
        assert np.array_equal(shot.raw.channels[name].codes, raw.channels[name][0])
    with h5py.File(path, "r") as f:  # the browsable mirror
        assert np.array_equal(f["analysis/model/a"][...], RESULTS["model"]["a"])
        assert f["analysis/model/poles"].shape == (4, 2)
        assert f["analysis/model"].attrs["order"] == 4
        assert f["analysis/fbsd_hz"].attrs["5"] == 7200.0
        assert json.loads(f["analysis"].attrs["pole_analysis_json"]) == RESULTS["pole_analysis"]
        assert list(f["analysis/excitation"].attrs["warnings"]) == ["pulse close to the rule"]
        assert f["analysis"].attrs["status"] == "ok"
        assert f["derived/record/reference"].attrs["units"] == "m/s^2"


def test_second_analysis_replaces_the_first(tmp_path: Path) -> None:
    path = write_raw_shot(tmp_path / "s.h5", known_raw(), known_meta())
    add_analysis(path, {}, error="identify: too short")
    add_analysis(path, {"fbsd_hz": {"5": 1.0}}, derived={"v": np.ones(3)})
    shot = read_shot(path)
    assert shot.state == "analysed" and shot.analysis_error is None
    assert shot.results == {"fbsd_hz": {"5": 1.0}} and list(shot.derived) == ["v"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.h5"]


def test_analysis_failure_is_recorded_and_raw_stays_intact(tmp_path: Path) -> None:
    raw = known_raw()
    path = write_raw_shot(tmp_path / "s.h5", raw, known_meta())
    partial = {"excitation": {"pulse_width_s": 3.9e-05}}
    add_analysis(path, partial, error="identify: the record is too short for order 12")
    shot = read_shot(path)
    assert shot.state == "analysis_failed"
    assert shot.analysis_error == "identify: the record is too short for order 12"
    assert shot.results == partial and shot.record is None
    for name in ("doppler", "response"):
        assert np.array_equal(shot.raw.channels[name].codes, raw.channels[name][0])
    with h5py.File(path, "r") as f:
        assert f["analysis"].attrs["status"] == "failed"


def test_failed_analysis_write_leaves_the_file_untouched(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = write_raw_shot(tmp_path / "s.h5", known_raw(), known_meta())
    before = sha256(path)
    with pytest.raises(ShotFileError, match=r"s\.h5: analysis results cannot be stored as JSON"):
        add_analysis(path, {"model": object()})
    assert sha256(path) == before

    def no_space(src: object, dst: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr("os.replace", no_space)
    with pytest.raises(ShotFileError, match=r"s\.h5: could not be written .*No space left"):
        add_analysis(path, RESULTS)
    assert sha256(path) == before and sorted(p.name for p in tmp_path.iterdir()) == ["s.h5"]
    with pytest.raises(ShotFileError, match="could not be written"):
        write_raw_shot(tmp_path / "t.h5", known_raw(), known_meta())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.h5"]  # nothing left of the failed write


# A child process that dies (SIGKILL, no clean-up at all) at the rename of a shot write.
CRASH_CHILD = textwrap.dedent(
    """
    import os, signal, sys
    import numpy as np
    import hopkinson.rig.shotfile_writer as sf
    from tests.rig.test_shotfile import known_raw, known_meta
    path, step = sys.argv[1], sys.argv[2]
    if step == "analysis":
        sf.write_raw_shot(path, known_raw(), known_meta())
    def die(src, dst):
        os.kill(os.getpid(), signal.SIGKILL)
    os.replace = die
    if step == "raw":
        sf.write_raw_shot(path, known_raw(), known_meta())
    else:
        sf.add_analysis(path, {"fbsd_hz": {"5": 1.0}}, derived={"v": np.ones(10)})
    """
)


def run_crash_child(path: Path, step: str) -> None:
    root = Path(__file__).resolve().parents[2]
    proc = subprocess.run([sys.executable, "-c", CRASH_CHILD, str(path), step], cwd=root,
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == -signal.SIGKILL, proc.stderr


def test_crash_between_tmp_write_and_rename_leaves_no_half_file(tmp_path: Path) -> None:
    run = RunFolder(tmp_path)
    run.shots_dir.mkdir()
    final = run.shot_path("s001-r1")
    run_crash_child(final, "raw")
    (tmp,) = run.shots_dir.glob(".s001-r1.h5.*.tmp")  # hopkinson.fileio's temporary beside it
    assert not final.exists() and tmp.exists()
    with pytest.raises(ShotFileError, match=r"s001-r1\.h5: no such file"):
        read_shot(final)
    with pytest.raises(ShotFileError, match=r"s001-r1\.h5\.\w+\.tmp: an unfinished temporary file"):
        read_shot(tmp)
    assert run.find_leftovers() == [tmp]
    lock = run.lock()
    try:
        assert run.clean_leftovers(lock) == [tmp]
    finally:
        lock.release()
    assert list(run.shots_dir.iterdir()) == []
    # The shot can then be written under its name as if nothing had happened.
    assert read_shot(write_raw_shot(final, known_raw(), known_meta())).state == "raw"


def test_crash_during_analysis_keeps_the_raw_file(tmp_path: Path) -> None:
    final = tmp_path / "s.h5"
    run_crash_child(final, "analysis")
    (tmp,) = tmp_path.glob(".s.h5.*.tmp")
    shot = read_shot(final)
    assert shot.state == "raw" and shot.results is None
    assert np.array_equal(shot.raw.channels["doppler"].codes, known_raw().channels["doppler"][0])
    assert RunFolder(tmp_path).find_leftovers() == [tmp]


def test_never_overwrites_a_shot(tmp_path: Path) -> None:
    path = write_raw_shot(tmp_path / "s.h5", known_raw(), known_meta())
    before = sha256(path)
    with pytest.raises(ShotFileError, match="already exists"):
        write_raw_shot(path, known_raw(), known_meta())
    assert sha256(path) == before


def test_truncated_file_gives_a_clear_error(tmp_path: Path) -> None:
    path = write_raw_shot(tmp_path / "s.h5", known_raw(), known_meta())
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(ShotFileError) as info:
        read_shot(path)
    message = str(info.value)
    assert message.startswith(f"{path}: not a readable HDF5 shot file (truncated or corrupt")
    assert "\n" not in message
    with pytest.raises(ShotFileError, match="not a readable HDF5"):
        add_analysis(path, {})
    path.write_bytes(b"")
    with pytest.raises(ShotFileError, match=r"s\.h5: not a readable HDF5 shot file"):
        read_shot(path)


def test_not_a_shot_file(tmp_path: Path) -> None:
    text = tmp_path / "notes.h5"
    text.write_text("time_s,reference,response\n")
    with pytest.raises(ShotFileError, match=r"notes\.h5: not a readable HDF5 shot file"):
        read_shot(text)
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["x"] = np.arange(3)
    with pytest.raises(ShotFileError, match=r"other\.h5: an HDF5 file but not a hopkinson shot file"):
        read_shot(other)
    with pytest.raises(ShotFileError, match=r"absent\.h5: no such file"):
        read_shot(tmp_path / "absent.h5")


def test_damaged_raw_data_is_detected_by_its_checksum(tmp_path: Path) -> None:
    path = write_raw_shot(tmp_path / "s.h5", known_raw(), known_meta())
    with h5py.File(path, "r") as f:
        offset = f["raw/doppler"].id.get_chunk_info(0).byte_offset
    with open(path, "r+b") as fh:
        fh.seek(offset + 100)
        fh.write(b"\x00\x11\x22\x33")
    read_shot(path, load_raw=False)  # meta still reads
    with pytest.raises(ShotFileError, match=r"s\.h5: damaged shot file: /raw/doppler cannot be read"):
        read_shot(path)


@pytest.mark.parametrize(
    ("raw", "meta", "reason"),
    [
        (RawShot({"doppler": (np.zeros(10, np.int16), 1.0, 0.0)}, 1e-8, 0), known_meta(), "lacks channel(s) response"),
        (RawShot({"doppler": (np.zeros(10), 1.0, 0.0), "response": (np.zeros(10, np.int16), 1.0, 0.0)}, 1e-8, 0),
         known_meta(), "'doppler' must hold int16 codes"),
        (RawShot({"doppler": (np.zeros(10, np.int16), 1.0, 0.0), "response": (np.zeros(9, np.int16), 1.0, 0.0)},
                 1e-8, 0), known_meta(), "different lengths"),
        (RawShot(known_raw(100).channels, 1e-8, 100), known_meta(),
         "trigger_index 100 outside 0..99"),
        (RawShot(known_raw(100).channels, 0.0, 0), known_meta(), "sample_interval_s must be > 0"),
        (RawShot({"doppler": (np.zeros(10, np.int16), float("nan"), 0.0), "response": (np.zeros(10, np.int16), 1.0, 0.0)},
                 1e-8, 0), known_meta(), "scale_v/offset_v must be finite"),
        (known_raw(100), known_meta(uuid="123"), "uuid '123' is not a UUID"),
        (known_raw(100), known_meta(utc_time="2026-01-01T10:00:00"), "must be UTC"),
        (known_raw(100), known_meta(utc_time="yesterday"), "is not ISO 8601"),
        (known_raw(100), known_meta(config={"when": object()}), "config cannot be stored as JSON"),
    ],
)
def test_write_validation(tmp_path: Path, raw: RawShot, meta: ShotMeta, reason: str) -> None:
    path = tmp_path / "bad.h5"
    with pytest.raises(ShotFileError) as info:
        write_raw_shot(path, raw, meta)
    assert str(info.value).startswith(f"{path}: ") and reason in str(info.value)
    assert list(tmp_path.iterdir()) == []


def test_codes_of_a_wider_integer_type_are_accepted_when_they_fit(tmp_path: Path) -> None:
    raw = RawShot({"doppler": (np.array([-32768, 0, 32767]), 1.0, 0.0),
                   "response": (np.array([1, 2, 3], dtype=np.int32), 1.0, 0.0)}, 1e-8, 0)
    shot = read_shot(write_raw_shot(tmp_path / "s.h5", raw, known_meta()))
    assert shot.raw.channels["doppler"].codes.dtype == np.int16
    assert list(shot.raw.channels["doppler"].codes) == [-32768, 0, 32767]
    too_wide = RawShot({"doppler": (np.array([40000]), 1.0, 0.0), "response": (np.array([1]), 1.0, 0.0)}, 1e-8, 0)
    with pytest.raises(ShotFileError, match="int16 codes"):
        write_raw_shot(tmp_path / "t.h5", too_wide, known_meta())


def test_config_snapshot_of_typed_sections_is_stored_in_json_form(tmp_path: Path) -> None:
    import dataclasses
    import datetime as dt
    import enum

    class Slope(enum.Enum):
        RISING = "POS"

    @dataclasses.dataclass(frozen=True)
    class Digitizer:
        resource: str
        trigger_slope: Slope
        calibration_file: Path

    config = {
        "digitizer": Digitizer("TCPIP0::127.0.0.1::5025::SOCKET", Slope.RISING, Path("/lab/cal.toml")),
        "calibrated_on": dt.date(2026, 3, 1),
        "gains": np.array([1.0, 10.0]),
    }
    shot = read_shot(write_raw_shot(tmp_path / "s.h5", known_raw(64), known_meta(config=config)))
    assert shot.meta.config == {
        "digitizer": {"resource": "TCPIP0::127.0.0.1::5025::SOCKET", "trigger_slope": "POS",
                      "calibration_file": "/lab/cal.toml"},
        "calibrated_on": "2026-03-01",
        "gains": [1.0, 10.0],
    }


# ----------------------------------------------------------------------------- self-describing files

UNITS = {"V", "s", "m/s^2", "m/s", "Hz", "1"}


def nexus_default_plot(f: h5py.File) -> tuple[h5py.Dataset, h5py.Dataset, list[h5py.Dataset]]:
    """(signal, axis, auxiliary signals) as a NeXus viewer finds them: root @default -> NXentry
    @default -> NXdata @signal / @axes (https://www.nexusformat.org/2014_How_to_find_default_data.html)."""
    assert f.attrs["NX_class"] == "NXroot"
    entry = f[f.attrs["default"]]
    assert entry.attrs["NX_class"] == "NXentry"
    data = entry[entry.attrs["default"]]
    assert data.attrs["NX_class"] == "NXdata"
    axes = [str(a) for a in data.attrs["axes"]]
    aux = [data[str(name)] for name in data.attrs.get("auxiliary_signals", [])]
    return data[str(data.attrs["signal"])], data[axes[0]], aux


def test_every_dataset_carries_units_in_one_spelling(tmp_path: Path) -> None:
    path = write_raw_shot(tmp_path / "s.h5", known_raw(), known_meta())
    record = Record(1e-6, np.ones(300), np.ones(300), start_time_s=-5e-5)
    add_analysis(path, {"reduction": {"response_unit": "m/s^2"}, **RESULTS}, record=record,
                 derived={"velocity_m_s": np.zeros(300)})
    seen: dict[str, str] = {}

    def visit(name: str, obj: object) -> None:
        if isinstance(obj, h5py.Dataset) and not name.startswith(("meta/", "truth/", "analysis/")):
            seen[name] = obj.attrs.get("units")

    with h5py.File(path, "r") as f:
        f.visititems(visit)
        assert f["derived/record/response"].attrs["units"] == "m/s^2"  # issue 13: it had none
        assert f["derived/record/reference"].attrs["units"] == "m/s^2"  # and was spelled m/s2
        assert f["derived/velocity_m_s"].attrs["units"] == "m/s"
        assert f["raw/response"].attrs["units"] == "V" and f["raw/time_s"].attrs["units"] == "s"
    assert {"raw/doppler", "derived/record/response", "entry/signals/response"} <= set(seen)  # (a hard-linked
    # time axis is visited once, under one of its names)
    assert all(unit in UNITS for unit in seen.values()), seen


def test_time_is_a_dimension_scale_and_the_default_plot_is_volts_against_time(tmp_path: Path) -> None:
    raw = known_raw()
    path = write_raw_shot(tmp_path / "s.h5", raw, known_meta())
    with h5py.File(path, "r") as f:
        for name in ("doppler", "response"):
            scale = f[f"raw/{name}"].dims[0][0]
            assert scale == f["raw/time_s"] and scale.is_scale
        expected_t = (np.arange(N) - TRIGGER) * 1e-8
        np.testing.assert_allclose(f["raw/time_s"][...], expected_t, rtol=0, atol=1e-20)
        signal, axis, aux = nexus_default_plot(f)
        assert axis == f["raw/time_s"] and signal.attrs["units"] == "V" and axis.attrs["units"] == "s"
        assert signal.dims[0][0] == f["raw/time_s"]
        codes, scale_v, offset_v, _ = raw.channels["response"]
        np.testing.assert_allclose(signal[...], codes * scale_v + offset_v, rtol=1e-6)  # float32 volts
        (doppler,) = aux
        np.testing.assert_allclose(doppler[...], raw.channels["doppler"][0] * 3.0517578125e-05 - 0.0125,
                                   rtol=1e-6, atol=1e-9)
    # The analysis rewrite keeps all of it valid (a byte copy: references survive) and adds the record.
    time_s = -5e-5 + np.arange(300) * 1e-6
    add_analysis(path, RESULTS, record=Record(1e-6, np.sin(time_s * 1e4), np.cos(time_s * 1e4), -5e-5))
    add_analysis(path, RESULTS, record=Record(1e-6, np.sin(time_s * 1e4), np.cos(time_s * 1e4), -5e-5))
    with h5py.File(path, "r") as f:
        assert f["raw/response"].dims[0][0] == f["raw/time_s"]
        assert nexus_default_plot(f)[0] == f["entry/signals/response"]
        record = f["entry/record"]
        assert record.attrs["NX_class"] == "NXdata" and record["response"] == f["derived/record/response"]
        np.testing.assert_allclose(f["derived/record/response"].dims[0][0][...], time_s)


@pytest.mark.parametrize("dtype", ["int8", "uint8", "int16", "uint16", "float32"])
def test_codes_keep_their_native_type_and_full_scale(tmp_path: Path, dtype: str) -> None:
    info = np.finfo(dtype) if dtype == "float32" else np.iinfo(dtype)
    lo, hi = (-1.0, 1.0) if dtype == "float32" else (float(info.min), float(info.max))
    codes = np.linspace(lo, hi, 64).astype(dtype)
    raw = RawShot({"doppler": RawChannel(codes, 0.01, -0.5, (lo, hi)), "response": (codes, 0.02, 0.0)}, 1e-8, 3)
    shot = read_shot(write_raw_shot(tmp_path / "s.h5", raw, known_meta()))
    got = shot.raw.channels["doppler"]
    assert got.codes.dtype == np.dtype(dtype) and np.array_equal(got.codes, codes)
    assert got.code_range == (lo, hi) and shot.raw.channels["response"].code_range is None
    np.testing.assert_allclose(shot.volts("doppler"), codes.astype(float) * 0.01 - 0.5)


def test_a_file_without_the_nexus_default_still_reads(tmp_path: Path) -> None:
    # Shot files written before the NeXus default and the time scale existed.
    path = write_raw_shot(tmp_path / "s.h5", known_raw(), known_meta())
    with h5py.File(path, "r+") as f:
        del f["entry"], f["raw/time_s"]
        for key in ("NX_class", "default"):
            del f.attrs[key]
    add_analysis(path, RESULTS, record=Record(1e-6, np.ones(50), np.ones(50)))
    shot = read_shot(path)
    assert shot.state == "analysed" and shot.record is not None and shot.raw.channels["doppler"].codes.size == N
