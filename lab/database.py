"""Where the lab's record lives and how it is opened: the URL, the engine, the schema's version.

The URL is, first found: a command's --database, `HOPKINSON_DATABASE_URL`, the rig
configuration's `[database] url`,
else SQLite in the user's data folder (`$XDG_DATA_HOME/hopkinson/lab.sqlite`, or the
platform's user data folder): nothing to set up. `postgresql://…` URLs use psycopg 3.

The schema is versioned by Alembic (migrations/ ships with the package). `open_database`
creates an empty database at the newest revision (first use), opens one at the newest
revision, and refuses any other: an older schema is upgraded only by `upgrade_database`
(`hopkinson lab upgrade`), never silently; a newer one (written by newer software) is refused
with both versions named.
"""

from __future__ import annotations

import os
from pathlib import Path

import sqlalchemy as sa
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from hopkinson.lab.errors import LabError
from sqlalchemy.engine import URL, Engine, make_url

URL_ENV = "HOPKINSON_DATABASE_URL"
MIGRATIONS = Path(__file__).with_name("migrations")
SQLITE_BUSY_TIMEOUT_S = 30.0
WRITER = "hopkinson_writer"  # execution option of a writing transaction (SQLite: BEGIN IMMEDIATE)  # a second writer waits for the first (WAL: readers never wait)


def data_folder() -> Path:
    """The user's data folder for hopkinson ($XDG_DATA_HOME/hopkinson, else the platform's)."""
    xdg = os.environ.get("XDG_DATA_HOME")
    if xdg:
        return Path(xdg) / "hopkinson"
    import platformdirs

    return Path(platformdirs.user_data_dir("hopkinson", appauthor=False))


def database_url(configured: str = "", explicit: str = "") -> str:
    """The database URL in force: `explicit` (a command's --database), else the environment, else
    `configured` (the rig configuration's), else the default SQLite file."""
    url = explicit.strip() or os.environ.get(URL_ENV, "").strip() or configured.strip()
    if url:
        return url
    return f"sqlite:///{data_folder() / 'lab.sqlite'}"


def redacted(url: str) -> str:
    """The URL without its password (for messages and logs)."""
    try:
        return make_url(url).render_as_string(hide_password=True)
    except (sa.exc.ArgumentError, ValueError):
        return "<unreadable database URL>"


def _driver_url(url: str) -> URL:
    try:
        parsed = make_url(url)
    except (sa.exc.ArgumentError, ValueError):
        raise LabError(f"database URL {url!r}: not a database URL (sqlite:///FILE or postgresql://…)") from None
    if parsed.drivername in ("postgresql", "postgres"):
        parsed = parsed.set(drivername="postgresql+psycopg")
    if parsed.get_backend_name() not in ("sqlite", "postgresql"):
        raise LabError(f"database URL {redacted(url)}: only sqlite and postgresql are supported")
    return parsed


def make_engine(url: str) -> Engine:
    """An engine for `url` (SQLite: its folder created, WAL, foreign keys, a busy timeout)."""
    parsed = _driver_url(url)
    if parsed.get_backend_name() == "sqlite":
        if parsed.database and parsed.database != ":memory:":
            Path(parsed.database).expanduser().parent.mkdir(parents=True, exist_ok=True)
        engine = sa.create_engine(parsed, connect_args={"timeout": SQLITE_BUSY_TIMEOUT_S})

        @sa.event.listens_for(engine, "connect")
        def _pragmas(dbapi_connection, _record):  # noqa: ANN001 (DB-API objects)
            dbapi_connection.isolation_level = None  # SQLAlchemy's BEGIN below, not pysqlite's
            cursor = dbapi_connection.cursor()
            cursor.execute("PRAGMA foreign_keys=ON")
            cursor.execute("PRAGMA journal_mode=WAL")
            cursor.close()

        @sa.event.listens_for(engine, "begin")
        def _begin(conn):  # noqa: ANN001
            # a writer (WRITER option) takes the write lock at once and waits its turn; readers never wait (WAL)
            conn.exec_driver_sql("BEGIN IMMEDIATE" if conn.get_execution_options().get(WRITER) else "BEGIN")

        return engine
    return sa.create_engine(parsed, pool_pre_ping=True, connect_args={"connect_timeout": 10})


def _alembic_config(connection: sa.Connection) -> Config:
    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS))
    config.attributes["connection"] = connection
    return config


def head_revision() -> str:
    """The newest schema revision this software knows."""
    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS))
    return ScriptDirectory.from_config(config).get_current_head()


def current_revision(engine: Engine) -> str | None:
    """The database's schema revision (None: an empty database)."""
    with engine.connect() as connection:
        return MigrationContext.configure(connection).get_current_revision()


def _known(revision: str) -> bool:
    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS))
    try:
        return ScriptDirectory.from_config(config).get_revision(revision) is not None
    except Exception:  # alembic's ResolutionError/CommandError: not one of ours
        return False


def check_schema(engine: Engine, url: str) -> None:
    """Create an empty database's schema; refuse an older or newer one (module doc)."""
    where = redacted(url)
    try:
        revision = current_revision(engine)
    except sa.exc.OperationalError as exc:
        raise LabError(f"database {where}: cannot be reached ({first_line(exc)})") from None
    head = head_revision()
    if revision == head:
        return
    if revision is None:
        with engine.connect() as connection:
            if sa.inspect(connection).get_table_names():
                raise LabError(f"database {where}: holds tables but no hopkinson schema version; not touched")
        upgrade_database(engine)
        return
    if not _known(revision):
        raise LabError(f"database {where}: schema version {revision} is newer than this software's "
                       f"({head}); use a newer hopkinson")
    raise LabError(f"database {where}: schema version {revision} is older than this software's ({head}); "
                   f"run `hopkinson lab upgrade` (back the database up first)")


def upgrade_database(engine: Engine) -> tuple[str | None, str]:
    """Migrate the schema to the newest revision in one transaction; (before, after)."""
    from alembic import command

    before = current_revision(engine)
    if before is not None and not _known(before):
        raise LabError(f"database schema version {before} is newer than this software's ({head_revision()}); "
                       f"use a newer hopkinson")
    with engine.begin() as connection:
        command.upgrade(_alembic_config(connection), "head")
    return before, head_revision()


def first_line(exc: BaseException) -> str:
    """One line for a database error (the driver's own message, else the exception's)."""
    text = str(getattr(exc, "orig", None) or exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__
