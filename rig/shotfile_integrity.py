"""Is a shot file sound? Its HDF5 checksums, its results' and its raw channels' SHA-256
(the layout: rig/shotfile.py): the one verification `report`, `analyse` and `lab import` share."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from hopkinson.rig.shotfile import RawChannel, RawShot, ShotFileError, open_shot

RAW_MISMATCH = "raw channels do not match their SHA-256 written with the shot (tampered or damaged)"


def raw_sha256(raw: RawShot) -> str:
    """SHA-256 of the raw channels as recorded: each role (sorted) with its code type, scale,
    offset and codes (little-endian), and the sampling; a re-analysis never changes it."""
    digest = hashlib.sha256(f"{raw.sample_interval_s!r}|{int(raw.trigger_index)}".encode())
    for role in sorted(raw.channels):
        channel = RawChannel(*raw.channels[role])
        codes = np.ascontiguousarray(channel.codes, dtype=channel.codes.dtype.newbyteorder("<"))
        digest.update(f"|{role}|{codes.dtype.str}|{codes.size}|{channel.scale_v!r}|{channel.offset_v!r}|".encode())
        digest.update(codes.tobytes())
    return digest.hexdigest()



def verify_shot(path: str | Path, recorded_raw_sha256: str | None = None) -> list[str]:
    """Every way the shot file is damaged or changed, one line each (empty: sound): the one
    verification `report`, `analyse` and `lab import` share. Each dataset is read whole
    (HDF5's fletcher32 checksum fails on a changed byte), each analysis' results JSON is
    compared with its SHA-256, and the raw channels' SHA-256 with the one written with the shot
    and with `recorded_raw_sha256` (the lab record's, kept from the shot's first import) —
    channels rewritten whole with h5py pass HDF5's checksums but not these. A file written
    before the checksums has none to compare: it still reads, only its damage cannot be seen."""
    path = Path(path)
    problems: list[str] = []
    read: dict[str, np.ndarray] = {}
    with open_shot(path) as f:
        def visit(name: str, obj: Any) -> None:
            if isinstance(obj, h5py.Dataset):
                try:
                    read[name] = obj[...]
                except (OSError, ValueError) as exc:
                    problems.append(f"/{name} fails its checksum ({str(exc).splitlines()[0][:120]})")
            elif isinstance(obj, h5py.Group) and "results_json" in obj.attrs:
                digest = obj.attrs.get("results_sha256")
                text = obj.attrs["results_json"]
                if digest is not None and hashlib.sha256(str(text).encode("utf-8")).hexdigest() != digest:
                    problems.append(f"/{name}: its results do not match their SHA-256")

        try:
            f.visititems(visit)
            written = f.attrs.get("raw_sha256")
            raw = f["raw"]
            channels = {str(role): RawChannel(read[f"raw/{role}"], float(raw[role].attrs["scale_v"]),
                                              float(raw[role].attrs["offset_v"]))
                        for role in raw.attrs["channels"]} if not problems else {}
            sampling = (float(raw.attrs["sample_interval_s"]), int(raw.attrs["trigger_index"]))
        except (OSError, RuntimeError, KeyError, ValueError) as exc:
            problems.append(f"the file's structure cannot be read ({exc})")
    if problems:
        return problems
    digest = raw_sha256(RawShot(channels, *sampling))  # from the codes just read: one pass over the file
    if written is not None and str(written) != digest:
        problems.append(RAW_MISMATCH)
    elif recorded_raw_sha256 is not None and recorded_raw_sha256 != digest:
        problems.append(f"raw channels' SHA-256 {digest[:12]}… differ from {recorded_raw_sha256[:12]}… kept by the "
                        f"lab's record since the shot's first import (tampered or damaged)")
    return problems


def require_sound(path: str | Path, recorded_raw_sha256: str | None = None) -> None:
    """ShotFileError naming every damage verify_shot finds."""
    problems = verify_shot(path, recorded_raw_sha256)
    if problems:
        raise ShotFileError(f"{path}: damaged shot file: {'; '.join(problems)}")
