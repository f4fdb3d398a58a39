"""Reading a TOML file a person gave (the rig configuration, a campaign plan) safely: one
ConfigError line naming the file for anything that is not one, never a traceback.

    doc, text = read_toml(path, "plan file", missing="no such plan file")

Only a regular file is read (a folder, a device such as /dev/zero or a pipe is refused before
any byte is read: a pipe is opened without waiting for a writer), at most MAX_TOML_BYTES of
it (a configuration or a plan is a few kB; more is not one), as UTF-8 text.
"""

from __future__ import annotations

import os
import stat
import tomllib
from pathlib import Path
from typing import Any

from hopkinson.rig.errors import ConfigError

MAX_TOML_BYTES = 1 << 20


def read_toml(path: str | os.PathLike[str], what: str = "configuration file",
              missing: str = "no such file") -> tuple[dict[str, Any], str]:
    """(the parsed document, its text); ConfigError "<path>: <what is wrong>" otherwise.
    `what` names the kind of file in the messages ("is a folder, not a plan file"), `missing`
    says that there is none."""
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise ConfigError(f"{path}: {missing}") from None
    except IsADirectoryError:
        raise ConfigError(f"{path}: is a folder, not a {what}") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror or exc}") from None
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        os.close(fd)
        if stat.S_ISDIR(mode):
            raise ConfigError(f"{path}: is a folder, not a {what}")
        raise ConfigError(f"{path}: not a regular file (a device, pipe or socket), not a {what}")
    with os.fdopen(fd, "rb") as fh:
        try:
            data = fh.read(MAX_TOML_BYTES + 1)
        except OSError as exc:
            raise ConfigError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if len(data) > MAX_TOML_BYTES:
        raise ConfigError(f"{path}: larger than {MAX_TOML_BYTES // 1024} KiB: not a {what}")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not UTF-8 text (byte {exc.start}): is it a binary file?") from None
    try:
        return tomllib.loads(text), text
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
