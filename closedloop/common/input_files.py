"""Input files read within limits: a size for each kind of file, checked before a byte is
parsed, and XML without entity declarations. Every refusal is a one-line
:class:`~closedloop.exceptions.ModelFileError` that names the file.

Sizes (:data:`SIZE_LIMITS`, bytes). PyYAML reads 50 to 200 kB a second and takes some
60 bytes of memory a byte of text: a 12 MB springs file took a minute and 750 MB before
its first error. The limits are far above any real robot's files and bound the time and
memory spent on a wrong one (a log, a mesh, a data set given by mistake).

XML entities. An entity declaration (``<!ENTITY ...>`` in the document type) can expand a
kilobyte into gigabytes (the "billion laughs") or pull in another file (an external
entity, ``SYSTEM "file:///..."``). Python's expat stops an amplification at its limit and
leaves external entities undefined; Pinocchio's URDF reader (tinyxml2) and assimp's
COLLADA reader (pugixml) do not expand entities at all, leaving ``&lol9;`` as text, so
that each reader fails on such a file in its own way, or not at all. Robot descriptions
and meshes have no use for entities: a file that declares one is refused here, before any
other reader sees it (:func:`read_xml`; meshes: :func:`refuse_xml_entities`).
"""

from __future__ import annotations

import io
import os
import xml.etree.ElementTree as ET
from collections.abc import Iterable
from pathlib import Path
from typing import BinaryIO
from xml.parsers import expat

from closedloop.exceptions import ModelFileError

#: Bytes of a megabyte, the unit of the messages.
MB = 1_000_000
#: Largest input file of each kind [bytes], checked before it is parsed:
#:
#: * ``"YAML"`` (closure, side, springs, measurement and parameter files): one line a
#:   joint, closure or measurement; 1 MB holds springs for 50,000 joints or some 5,000
#:   measurements, and PyYAML needs 6 s (springs) to 22 s (measurements in flow style) to
#:   read it: measurements in quantity belong in CSV.
#: * ``"CSV"`` (measurement files, a map's points): Python's csv reads some 4 MB a second;
#:   16 MB holds some 250,000 measurements or points, hours of computation.
#: * ``"XML"`` (URDF, MJCF, SDF robot files): the largest real descriptions are a few MB
#:   (hundreds of links from a CAD exporter, an MJCF with mesh vertices or a height field
#:   written inline; mesh files are separate and not counted); ElementTree holds about ten
#:   times the file in memory (measured on a URDF of links), so 64 MB stays below a GB.
SIZE_LIMITS = {"YAML": 1 * MB, "CSV": 16 * MB, "XML": 64 * MB}
_KINDS = {
    "YAML": "YAML files (closure, side, springs, measurement, parameter files)",
    "CSV": "CSV files (measurements, map points)",
    "XML": "robot files (URDF, MJCF, SDF)",
}
#: Bytes read at a time when meshes are scanned for entity declarations.
_CHUNK = 1 << 16


def read_bytes(path: str | Path, where: str, kind: str) -> bytes:
    """The bytes of the file ``path``, at most :data:`SIZE_LIMITS` ``[kind]`` of them.

    Args:
        path: the file.
        where: the file as the messages name it (``"springs file 'k.yaml'"``).
        kind: ``"YAML"``, ``"CSV"`` or ``"XML"``.

    Raises:
        ModelFileError: the file cannot be read, or is larger than the limit (its size
            and the limit named; a regular file is not read then, a pipe up to one byte
            beyond the limit).
    """
    limit = SIZE_LIMITS[kind]
    try:
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size  # 0 for a pipe
            data = f.read(limit + 1) if size <= limit else b""
    except OSError as e:
        raise ModelFileError(f"{where} cannot be read: {e.strerror}") from None
    if size > limit or len(data) > limit:
        shown = f"{size} bytes ({size / MB:.3g} MB)" if size > limit else f"over {limit} bytes"
        raise ModelFileError(
            f"{where} is {shown}, above the limit of {limit / MB:g} MB for {_KINDS[kind]}; "
            "expected a smaller file (is it the right one?)"
        )
    return data


def read_text(path: str | Path, where: str, kind: str) -> str:
    """The text of ``path`` (UTF-8, a byte-order mark dropped), as :func:`read_bytes`.

    Raises:
        ModelFileError: as :func:`read_bytes`, or the file is not UTF-8 text.
    """
    try:
        return read_bytes(path, where, kind).decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise ModelFileError(f"{where} is not a text file (UTF-8): {e}") from None


def read_xml(path: str | Path, where: str) -> ET.Element:
    """The root element of the XML file ``path`` (a robot file), within the ``"XML"``
    size limit, refused if it declares an entity.

    Raises:
        ModelFileError: as :func:`read_bytes`, an entity declaration (its name given), or
            the file is not valid XML (expat's message).
    """
    data = read_bytes(path, where, "XML")
    _refuse_entities(io.BytesIO(data), where)
    try:
        return ET.fromstring(data)
    except ET.ParseError as e:
        raise ModelFileError(f"{where} is not valid XML: {e}") from None


def refuse_xml_entities(paths: Iterable[str], where: str) -> None:
    """Refuse the files among ``paths`` (meshes) that are XML (COLLADA ``.dae``...) and
    declare an entity; files that are not XML (STL, OBJ) and paths that name no file
    (Pinocchio's primitives) pass. Only the prologue is read: declarations come before
    the root element.

    Args:
        paths: the files, each checked once.
        where: what they belong to (``"robot file 'arm.urdf'"``), for the message.

    Raises:
        ModelFileError: naming the mesh, the entity and ``where``.
    """
    for path in sorted(set(paths)):
        if path and Path(path).is_file():
            with open(path, "rb") as f:
                _refuse_entities(f, f"{where}: mesh {path!r}")


class _Declared(Exception):
    pass


class _Root(Exception):
    pass


def _refuse_entities(stream: BinaryIO, where: str) -> None:
    """:class:`ModelFileError` if the XML read from ``stream`` declares an entity before
    its root element; text that is not XML is left to its reader."""
    parser = expat.ParserCreate()

    def declared(name, *_):
        raise _Declared(name)

    def root(*_):
        raise _Root

    parser.EntityDeclHandler = declared
    parser.StartElementHandler = root
    try:
        while chunk := stream.read(_CHUNK):
            parser.Parse(chunk, False)
        parser.Parse(b"", True)
    except _Declared as e:
        raise ModelFileError(
            f"{where} declares the XML entity {e.args[0]!r} (<!ENTITY> in its DOCTYPE); "
            "expected XML without entity declarations (an entity may expand without bound "
            "or read another file)"
        ) from None
    except (_Root, expat.ExpatError):
        return
