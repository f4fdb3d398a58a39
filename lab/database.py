"""Where the lab's record lives and how it is opened: the URL, the engine, the schema's version.

The URL is, first found: a command's --database, `HOPKINSON_DATABASE_URL`, the rig
configuration's `[database] url`,
else SQLite in the user's data folder (`$XDG_DATA_HOME/hopkinson/lab.sqlite`, or the
platform's user data folder): nothing to set up. `postgresql://…` URLs use psycopg 3.

A SQLite URL names an absolute path whose folder exists (the default's folder is created):
a mistyped URL is refused, never a new empty database somewhere else.

The schema is versioned by Alembic (migrations/ ships with the package). `check_schema`
creates an empty database at the newest revision (first use), opens one at the newest
revision, and refuses any other: an older schema is upgraded only by `upgrade_database`
(`hopkinson lab upgrade`, as the owner role on PostgreSQL), never silently; a newer one
(written by newer software) is refused with both versions named.

`failure_of(exc)` sorts what a database said into the three things a caller does about it:
AWAY (try again later: the record waits in the spool), SETUP (the configuration is wrong, a
password or a privilege: the record waits, the operator is told to fix it) and REJECTED (the
record itself was refused: it is set aside with the reason, lab.spool).
"""

from __future__ import annotations

import os
from enum import StrEnum
from pathlib import Path

import sqlalchemy as sa
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy.engine import URL, Engine, make_url

from hopkinson.lab.errors import DatabaseAway, LabError

URL_ENV = "HOPKINSON_DATABASE_URL"
MIGRATIONS = Path(__file__).with_name("migrations")
SQLITE_BUSY_TIMEOUT_S = 30.0
POSTGRES_LOCK_TIMEOUT_S = 20.0  # a statement waiting longer on a lock fails (the record is spooled)
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


def _sqlite_file(url: str, parsed: URL) -> Path | None:
    """The SQLite file a URL names (None: in memory); LabError for a relative path or a folder
    that does not exist (but for the default location's, which is created)."""
    if not parsed.database or parsed.database == ":memory:":
        return None
    path = Path(parsed.database).expanduser()
    if not path.is_absolute():
        raise LabError(f"database URL {url!r}: a SQLite file needs an absolute path "
                       f"(sqlite:////absolute/path/lab.sqlite), not one relative to the working folder")
    if not path.parent.is_dir():
        if path.parent == data_folder():
            path.parent.mkdir(parents=True, exist_ok=True)
        else:
            raise LabError(f"database URL {url!r}: folder {path.parent} does not exist (a mistyped URL?); "
                           f"nothing created")
    return path


def sqlite_missing(url: str) -> Path | None:
    """The SQLite file `url` names when it does not exist yet (None otherwise, or not SQLite)."""
    parsed = _driver_url(url)
    if parsed.get_backend_name() != "sqlite":
        return None
    path = _sqlite_file(url, parsed)
    return path if path is not None and not path.exists() else None


def make_engine(url: str) -> Engine:
    """An engine for `url` (SQLite: WAL, foreign keys, a busy timeout; PostgreSQL: a lock
    timeout, so a locked table makes a record wait in the spool rather than hang)."""
    parsed = _driver_url(url)
    if parsed.get_backend_name() == "sqlite":
        _sqlite_file(url, parsed)
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
    return sa.create_engine(parsed, pool_pre_ping=True, connect_args={
        "connect_timeout": 10, "options": f"-c lock_timeout={int(POSTGRES_LOCK_TIMEOUT_S * 1000)}"})


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


def known_revision(revision: str) -> bool:
    """Whether `revision` is one of this software's migrations (else: written by newer software)."""
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
        kind = DatabaseAway if failure_of(exc) is Failure.AWAY else LabError
        raise kind(f"database {where}: cannot be reached ({first_line(exc)})") from None
    head = head_revision()
    if revision == head:
        return
    if revision is None:
        with engine.connect() as connection:
            if sa.inspect(connection).get_table_names():
                raise LabError(f"database {where}: holds tables but no hopkinson schema version; not touched")
        try:
            upgrade_database(engine)
        except sa.exc.ProgrammingError as exc:  # PostgreSQL: the rig's role may not create tables
            raise LabError(f"database {where}: the schema cannot be created with this role ({first_line(exc)}); "
                           f"run `hopkinson lab upgrade` as the database's owner role (docs/lab-record.md)") from None
        return
    if not known_revision(revision):
        raise LabError(f"database {where}: schema version {revision} is newer than this software's "
                       f"({head}); use a newer hopkinson")
    raise LabError(f"database {where}: schema version {revision} is older than this software's ({head}); "
                   f"run `hopkinson lab upgrade` (it backs a SQLite file up first; PostgreSQL: pg_dump first, "
                   f"docs/lab-record.md)")


def upgrade_database(engine: Engine) -> tuple[str | None, str]:
    """Migrate the schema to the newest revision in one transaction; (before, after)."""
    from alembic import command

    before = current_revision(engine)
    if before is not None and not known_revision(before):
        raise LabError(f"database schema version {before} is newer than this software's ({head_revision()}); "
                       f"use a newer hopkinson")
    with engine.connect() as connection:
        sqlite = engine.dialect.name == "sqlite"
        if sqlite:  # batch migrations copy tables: foreign keys are checked after, not during
            connection.connection.dbapi_connection.execute("PRAGMA foreign_keys=OFF")
        try:
            with connection.begin():
                command.upgrade(_alembic_config(connection), "head")
                if sqlite and connection.exec_driver_sql("PRAGMA foreign_key_check").first() is not None:
                    raise LabError("the migration left a broken foreign key; rolled back")
        finally:
            if sqlite:
                connection.connection.dbapi_connection.execute("PRAGMA foreign_keys=ON")
    return before, head_revision()


def first_line(exc: BaseException) -> str:
    """One line for a database error (the driver's own message, else the exception's)."""
    text = str(getattr(exc, "orig", None) or exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


class Failure(StrEnum):
    """What a database's refusal means for the record (module doc)."""

    AWAY = "away"
    SETUP = "setup"
    REJECTED = "rejected"


_SETUP_WORDS = ("password authentication failed", "authentication failed", "permission denied",
                "must be owner", "role", "does not exist", "no pg_hba.conf entry", "readonly database",
                "attempt to write a readonly")


def failure_of(exc: BaseException) -> Failure:
    """AWAY, SETUP or REJECTED for an exception met while recording (module doc)."""
    if isinstance(exc, LabError):
        return Failure(exc.failure)
    text = first_line(exc).lower()
    if isinstance(exc, sa.exc.DBAPIError) and any(word in text for word in _SETUP_WORDS):
        return Failure.SETUP
    if isinstance(exc, sa.exc.DataError | sa.exc.IntegrityError):
        return Failure.REJECTED
    if isinstance(exc, sa.exc.ProgrammingError):
        return Failure.SETUP
    return Failure.AWAY
