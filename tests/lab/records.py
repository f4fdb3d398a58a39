"""Shot records made up for the lab's tests: known figures, so what the record gives back can be
compared with what went in."""

from __future__ import annotations

import hashlib
import uuid as uuid_module

from hopkinson.analysis.key_figures import Figure
from hopkinson.lab.records import ReferenceLink, ShotRecord


def figure(value: float, u: float) -> Figure:
    return Figure(value, u, (value - 2 * u, value + 2 * u))


def made_up_record(serial: str = "SN-7", *, utc: str = "2026-03-01T10:00:00Z", sensitivity: float = 1.0,
                   u: float = 0.002, campaign: str = "", rig: str = "HB-1", uid: str | None = None,
                   raw: bytes | None = None, state: str = "analysed", analysis: str = "a",
                   campaign_uuid: str | None = None, simulated: bool = False, operator: str = "tech A",
                   peak_m_s2: float = 4.9e5, context: dict | None = None) -> ShotRecord:
    """A made-up shot record; a campaign named but not given a UUID gets one derived from its
    name (so the tests' campaigns by name stay one campaign each)."""
    uid = uid or str(uuid_module.uuid4())
    raw_sha = hashlib.sha256(raw if raw is not None else uid.encode()).hexdigest()
    figures = {"sensitivity": figure(sensitivity, u), "shock_sensitivity": figure(1.6 * sensitivity, u),
               "natural_frequency_hz": figure(27e3, 5.0), "damping_ratio": figure(0.05, 1e-4),
               "fbsd_5_hz": figure(5.9e3, 2.0), "fbsd_10_hz": None} if state == "analysed" else {}
    return ShotRecord(
        uuid=uid, raw_sha256=raw_sha, file_sha256=hashlib.sha256((uid + analysis).encode()).hexdigest(),
        path=f"/shots/{uid}.h5", state=state, operator=operator, utc_time=utc, accelerometer_model="ACC-20k",
        accelerometer_serial=serial, pressure_bar=2.0, projectile=3, rig=rig, campaign=campaign,
        campaign_uuid=campaign_uuid or (str(uuid_module.uuid5(uuid_module.NAMESPACE_URL, campaign)) if campaign else ""),
        simulated_marks=("simulator's truth",) if simulated else (), pulse_width_s=40e-6, context=context or {},
        shot_name=uid[:8], response_unit="m/s^2", peak_acceleration_m_s2=peak_m_s2, figures=figures,
        reference_chain=(ReferenceLink("interferometer", "PTB-1234", "PTB", 5e-4, "2027-06-30"),),
    )


def made_up_results(sensitivity: float, u: float, f_n_hz: float = 27e3) -> dict:
    """A shot's results dict as the analysis stores it (only what the key figures read)."""
    return {
        "model": {"dc_gain": sensitivity, "order": 2},
        "identification": {"main_mode": {"natural_frequency_hz": f_n_hz, "damping_ratio": 0.05 * sensitivity}},
        "reduction": {"response_unit": "m/s^2", "shock_sensitivity": 1.6 * sensitivity,
                      "peak_acceleration_m_s2": 4.9e5},
        "fbsd_hz": {"5": 5.9e3, "10": 8.1e3},
        "uncertainty": {"dc_gain": {"value": sensitivity, "u": u, "interval": [sensitivity - 2 * u, sensitivity + 2 * u]},
                        "main_mode": {"natural_frequency_hz": {"value": f_n_hz, "u": 4.0,
                                                               "interval": [f_n_hz - 8, f_n_hz + 8]},
                                      "damping_ratio": {"value": 0.05, "u": 1e-4, "interval": [0.0498, 0.0502]}},
                        "fbsd_hz": {"5": {"value": 5.9e3, "u": 3.0, "interval": [5894.0, 5906.0]}}},
    }


def write_made_up_shot(path, *, serial: str = "SN-7", campaign: str | None = None, sensitivity: float = 1.0,
                       u: float = 0.002, utc: str = "2026-03-01T10:00:00Z", config: dict | None = None,
                       simulated: bool = False, campaign_uuid: str | None = None, instruments: dict | None = None,
                       operator: str = "tech A"):
    """A real shot file (rig.shotfile) with short made-up channels and made-up results; its meta."""
    import numpy as np

    from hopkinson.rig.shotfile import RawShot, ShotMeta
    from hopkinson.rig.shotfile_writer import add_analysis, write_raw_shot

    rng = np.random.default_rng(abs(hash(str(path))) % 2**32)
    raw = RawShot({"doppler": (rng.integers(-2000, 2000, 512).astype(np.int16), 1e-3, 0.0),
                   "response": (rng.integers(-2000, 2000, 512).astype(np.int16), 2e-3, 0.01)}, 1e-8, 64)
    meta = ShotMeta(operator=operator, accelerometer_model="ACC-20k", accelerometer_serial=serial, pressure_bar=2.0,
                    projectile=3, campaign_id=campaign, shot_id=path.stem, utc_time=utc, config=config or {},
                    campaign_uuid=campaign_uuid or (campaign and str(uuid_module.uuid5(uuid_module.NAMESPACE_URL,
                                                                                       str(path.parent.parent)))),
                    instruments=instruments or {"digitizer": "ACME,SCOPE-9,123,1.0"},
                    simulated_truth={"made_up": True} if simulated else None)
    write_raw_shot(path, raw, meta)
    add_analysis(path, made_up_results(sensitivity, u))
    return meta
