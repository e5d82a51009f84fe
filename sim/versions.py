"""The simulated controller's software version: which PolyScope 5 release it presents itself as.

One :class:`SoftwareVersion` per controller (:attr:`sim.core.Core.version`), reported the same everywhere it appears:
the dashboard's ``PolyscopeVersion`` and ``version``, the primary interface's version message, RTDE's
``get_urcontrol_version``; and it decides what that release has (the RTDE fields of :mod:`sim.rtde_fields`, the
dashboard commands of :mod:`sim.dashboard`, the real-time package's length in :mod:`sim.realtime_packages`).

The simulator is an e-Series controller: PolyScope 5.0 up to `NEWEST`, the newest release whose RTDE fields it
knows (a later release's new fields would be missing here). CB3 controllers (3.x) and PolyScope X (10.x) are other
controllers (other RTDE rates, interfaces and script sets) and are refused.
"""

from __future__ import annotations

import datetime
import re
from dataclasses import dataclass


@dataclass(frozen=True, order=True)
class SoftwareVersion:
    """A PolyScope release: major.minor.bugfix and its build number (0: the simulator knows no build of it).

    Ordered by (major, minor, bugfix, build); compare with a plain tuple through :meth:`at_least`.
    """

    major: int
    minor: int
    bugfix: int
    build: int = 0

    @property
    def release(self) -> tuple[int, int, int]:
        return (self.major, self.minor, self.bugfix)

    def at_least(self, release: tuple[int, int, int]) -> bool:
        """True when this version is ``release`` (major, minor, bugfix) or later."""
        return self.release >= release

    @property
    def words(self) -> tuple[int, int, int, int]:
        """The four numbers RTDE's ``get_urcontrol_version`` answers and the version message carries."""
        return (self.major, self.minor, self.bugfix, self.build)

    @property
    def text(self) -> str:
        """``5.11.6.108949``: the dashboard's ``version`` reply."""
        return ".".join(str(v) for v in self.words)

    @property
    def build_date(self) -> datetime.date | None:
        """The release's build date where the simulator knows it (`KNOWN_BUILDS`), else None."""
        known = KNOWN_BUILDS.get(self.release)
        return known[1] if known and known[0] == self.build else None

    @property
    def polyscope_text(self) -> str:
        """The dashboard's ``PolyscopeVersion`` reply: ``URSoftware 5.11.6.108949 (Jul 27 2021)``."""
        date = self.build_date
        return f"URSoftware {self.text} ({f'{date:%b %d %Y}' if date else 'build date unknown'})"

    @property
    def message_build_date(self) -> str:
        """The primary interface's version message's build date: ``27-07-2021, 12:00:00``."""
        date = self.build_date
        return f"{date:%d-%m-%Y}, 12:00:00" if date else "unknown"


#: Releases whose build number and date the simulator knows: (major, minor, bugfix) -> (build, build date).
#: 5.11.6: the one the simulator reported before the version became a setting; 5.19.0: the dashboard reply shown in
#: Universal Robots' C++ client library's installation guide (``URSoftware 5.19.0.1210631 (Oct 23 2024)``).
KNOWN_BUILDS: dict[tuple[int, int, int], tuple[int, datetime.date]] = {
    (5, 11, 6): (108949, datetime.date(2021, 7, 27)),
    (5, 19, 0): (1210631, datetime.date(2024, 10, 23)),
}

#: The newest release whose RTDE fields the simulator knows (UR's RTDE guide as of PolyScope 5.26).
NEWEST = (5, 26, 0)
#: The version a controller reports unless told otherwise.
DEFAULT = SoftwareVersion(5, 11, 6, 108949)
#: The release that brought the pendant's local / remote control switch (ur_rtde 1.6.5 asks ``is in remote control``
#: only from 5.6; UR's C++ client library's dashboard table lists that command from 5.6.0).
REMOTE_CONTROL_SINCE = (5, 6, 0)

_PATTERN = re.compile(r"(\d+)\.(\d+)(?:\.(\d+))?(?:\.(\d+))?")


def parse_polyscope(text) -> SoftwareVersion:
    """``"5.4.0"``, ``"5.4"`` or ``"5.11.6.108949"`` as a :class:`SoftwareVersion`; ValueError (one line, naming the
    setting) for anything the simulator cannot be. Without a build number, the known build of that release if any,
    else 0."""
    if isinstance(text, SoftwareVersion):
        version = text
    else:
        m = _PATTERN.fullmatch(str(text).strip()) if isinstance(text, str) else None
        if m is None:
            raise ValueError(f"polyscope: give a PolyScope 5 version such as 5.11.6 or 5.4.0, got {text!r}")
        major, minor, bugfix = int(m.group(1)), int(m.group(2)), int(m.group(3) or 0)
        known = KNOWN_BUILDS.get((major, minor, bugfix))
        build = int(m.group(4)) if m.group(4) is not None else (known[0] if known else 0)
        version = SoftwareVersion(major, minor, bugfix, build)
    if version.major in (1, 3):
        raise ValueError(f"polyscope: {version.text} is a CB3 controller's version; the simulator is an e-Series "
                         "controller (PolyScope 5.x)")
    if version.major == 10:
        raise ValueError(f"polyscope: {version.text} is PolyScope X; the simulator is an e-Series controller "
                         "(PolyScope 5.x)")
    if version.major != 5:
        raise ValueError(f"polyscope: {version.text} is no PolyScope release; the simulator is an e-Series "
                         "controller (PolyScope 5.x)")
    if version.release > NEWEST:
        raise ValueError(f"polyscope: {version.text} is newer than {'.'.join(map(str, NEWEST))}, the newest release "
                         "whose RTDE fields the simulator knows")
    for name, value in (("bugfix number", version.bugfix), ("build number", version.build)):
        if value >= 1 << 31:
            raise ValueError(f"polyscope: {name} {value} does not fit the version message's int32")
    return version


__all__ = ["SoftwareVersion", "parse_polyscope", "DEFAULT", "NEWEST", "KNOWN_BUILDS", "REMOTE_CONTROL_SINCE"]
