"""rig.toml's sections about the lab and the bar: [lab] (with [[lab.reference_chain]] and
[[lab.signatories]]),
[database] and [bar] (with [[bar.projectiles]]); rig/config.py holds the instruments' and
gathers them all in RigConfig. Each key is one field with its type, default, bounds and
description (drivers/config_fields.py)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from datetime import date
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, Field

from hopkinson.drivers.config_fields import SECTION, Flag, Hint, Int, Number, Text

# The names of analysis.bar.MATERIALS, written here so that reading a configuration does not
# import the bar model (NumPy and SciPy: half a second for every command); a test holds the two
# equal.
BAR_MATERIALS = ("C45", "Ti-6Al-4V", "PA6", "Al-7075")
BAR_MOUNTS = ("separating", "bonded")  # analysis.bar.geometry.MOUNTS, the same way
Material = Annotated[Literal[BAR_MATERIALS], Field(description="analysis.bar.MATERIALS"),  # type: ignore[valid-type]
                     Hint("analysis.bar.MATERIALS")]
Length = Annotated[Number, Field(gt=0, le=20)]
Diameter = Annotated[Number, Field(gt=0, le=1)]


def _iso_date(text: str) -> str:
    if text:
        try:
            date.fromisoformat(text)
        except ValueError:
            raise ValueError(f"a date YYYY-MM-DD (as a string), got {text!r}") from None
    return text


def _budget_input(name: str) -> str:
    """An [uncertainty] input's name (UncertaintyConfig's *_rel keys), or ""."""
    from hopkinson.rig.config import UncertaintyConfig

    inputs = [f.name for f in dataclasses.fields(UncertaintyConfig) if f.name.endswith("_rel")]
    if name and name not in inputs:
        raise ValueError(f"one of {', '.join(inputs)} (the [uncertainty] input it is), got {name!r}")
    return name


def _not_blank(text: str) -> str:
    if not text.strip():
        raise ValueError("must not be empty")
    return text


@dataclass(frozen=True)
class ReferenceCertificateConfig:
    """[[lab.reference_chain]]: one item of the rig's reference chain and its own certificate
    (printed on every certificate as its traceability); due "YYYY-MM-DD"."""

    __pydantic_config__ = SECTION
    item: Annotated[Text, AfterValidator(_not_blank)]
    certificate: Annotated[Text, AfterValidator(_not_blank)]
    issued_by: Text = ""
    u_rel: Annotated[Number, Field(ge=0, le=1, description="relative standard uncertainty, k = 1 "
                                                          "(0: not stated)")] = 0.0
    due: Annotated[Text, AfterValidator(_iso_date), Field(description="re-calibration due, YYYY-MM-DD")] = ""
    budget: Annotated[Text, AfterValidator(_budget_input), Field(description=(
        "the [uncertainty] input this item's u_rel is (e.g. grating_pitch_rel): a certificate is refused when "
        "the two disagree (hopkinson.lab.certificate); \"\": not an input of the budget"))] = ""


@dataclass(frozen=True)
class SignatoryConfig:
    """[[lab.signatories]]: a person who may authorise certificates, and their role."""

    __pydantic_config__ = SECTION
    name: Annotated[Text, AfterValidator(_not_blank)]
    role: Annotated[Text, AfterValidator(_not_blank)]


@dataclass(frozen=True)
class LabConfig:
    """[lab]: the calibration lab as its certificates name it (hopkinson.lab)."""

    __pydantic_config__ = SECTION
    name: Text = ""
    address: Text = ""
    accreditation: Annotated[Text, Field(description='e.g. "DAkkS D-K-12345-01-00" ("": not accredited)')] = ""
    certificate_prefix: Annotated[Text, Field(pattern=r"^[A-Z0-9]{1,12}$", description=(
        "certificates are numbered <prefix>-<year>-<sequence>")), Hint("1 to 12 capital letters or digits")] = "HB"
    rig: Annotated[Text, Field(description="this rig's name in the lab's record (\"\": the file's name)")] = ""
    decision_rule: Annotated[Literal["simple", "guarded"], Field(description=(
        "simple: ILAC-G8 w = 0; guarded: w = U"))] = "simple"
    reference_chain: tuple[ReferenceCertificateConfig, ...] = ()
    signatories: Annotated[tuple[SignatoryConfig, ...], Field(description=(
        "who may authorise a certificate (none: no certificate can be authorised)"))] = ()
    country: Annotated[Text, Field(pattern=r"^([A-Z]{2})?$", description=(
        "ISO 3166-1 alpha-2 code of the lab (a Digital Calibration Certificate states it)")),
        Hint('an ISO 3166-1 alpha-2 code such as "DE"')] = ""


def _database_url(url: str) -> str:
    scheme = url.split(":", 1)[0].split("+", 1)[0]
    if url and scheme not in ("sqlite", "postgresql", "postgres"):
        raise ValueError(f"a sqlite:///FILE or postgresql://… URL, got scheme {scheme!r}")
    return url


@dataclass(frozen=True)
class DatabaseConfig:
    """[database]: where the lab's record lives ("" : SQLite in the user's data folder;
    HOPKINSON_DATABASE_URL overrides). Never copied into shot files (it may hold a password)."""

    __pydantic_config__ = SECTION
    url: Annotated[Text, AfterValidator(_database_url), Field(description="sqlite:///FILE or postgresql://…")] = ""


@dataclass(frozen=True)
class BarSegmentConfig:
    """A uniform piece of a projectile: material (analysis.bar.MATERIALS), length, diameter."""

    __pydantic_config__ = SECTION
    material: Material
    length_m: Length
    diameter_m: Diameter


@dataclass(frozen=True)
class BarProjectileConfig:
    """[[bar.projectiles]]: one projectile, its segments from the impact face backwards."""

    __pydantic_config__ = SECTION
    number: Annotated[Int, Field(ge=1, le=3, description="the projectile's position in the loader"),
                      Hint("a position of the loader: plans and shots take 1, 2 or 3")]
    segments: tuple[BarSegmentConfig, ...]
    description: Text = ""
    uses_spacer: Flag = True
    contact_stiffness_n_m: Annotated[Number, Field(ge=0, le=1e12, description=(
        "the impact face's contact spring at 1 mm; 0: flat and rigid")), Hint("0: flat and rigid")] = 0.0
    contact_exponent: Annotated[Number, Field(ge=1, le=3, description=(
        "p of F = k·δ₁·(δ/δ₁)^p: 1 a linear spring, 1.5 Hertz's")), Hint("1: a linear spring, 1.5: Hertz's")] = 1.0


@dataclass(frozen=True)
class BarConfig:
    """[bar]: the rig's physics for shot planning and the first shot's pressure (analysis.bar);
    every key has the paper's rig as its default, and no projectiles listed means the paper's three."""

    __pydantic_config__ = SECTION
    material: Material = "Ti-6Al-4V"
    length_m: Length = 1.6
    diameter_m: Diameter = 0.016
    spacer_material: Material = "Al-7075"
    spacer_length_m: Annotated[Number, Field(ge=0, le=1, description="0: no spacer"), Hint("0: no spacer")] = 0.003
    base_length_m: Annotated[Length, Field(description="the raster base (the bar's material and diameter)")] = 0.010
    sensor_mass_kg: Annotated[Number, Field(ge=0, le=10)] = 0.005
    barrel_length_m: Length = 1.5
    launcher_efficiency: Annotated[Number, Field(gt=0, le=1)] = 0.348
    mount: Annotated[Literal[BAR_MOUNTS], Field(description=(  # type: ignore[valid-type]
        "the object on the bar's end: separating (flies off) | bonded (stays on)"))] = "separating"
    projectiles: tuple[BarProjectileConfig, ...] = ()

    def rig(self) -> Any:
        """The analysis.bar.BarRig this table describes."""
        from hopkinson.analysis.bar import PAPER_RIG, BarRig, Launcher, Projectile, Segment

        projectiles = tuple(
            Projectile(p.number, p.description or f"projectile No. {p.number}",
                       tuple(Segment(s.material, s.length_m, s.diameter_m) for s in p.segments), p.uses_spacer,
                       p.contact_stiffness_n_m or None, p.contact_exponent)
            for p in self.projectiles) or PAPER_RIG.projectiles
        spacer = Segment(self.spacer_material, self.spacer_length_m, self.diameter_m) if self.spacer_length_m else None
        return BarRig(Segment(self.material, self.length_m, self.diameter_m), spacer,
                      Segment(self.material, self.base_length_m, self.diameter_m), self.sensor_mass_kg, projectiles,
                      Launcher(self.barrel_length_m, self.launcher_efficiency), self.mount)
