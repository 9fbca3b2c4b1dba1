"""XML input files for the tests of refused XML (a plain module: ``tests/`` is on
``sys.path``): entity declarations that amplify or read another file, a one-link SDF
robot, a one-triangle COLLADA mesh."""

from __future__ import annotations

from pathlib import Path

#: An entity-amplification ("billion laughs") document type: 10^9 "lol" from 1 kB.
LAUGHS = (
    '<!DOCTYPE root [\n <!ENTITY lol "lol">\n'
    + "".join(
        f' <!ENTITY lol{i} "{("&lol" + ("" if i == 1 else str(i - 1)) + ";") * 10}">\n'
        for i in range(1, 10)
    )
    + "]>\n"
)
#: An external entity: the text of another file.
EXTERNAL = '<!DOCTYPE root [ <!ENTITY lol9 SYSTEM "file:///etc/hostname"> ]>\n'
HOSTILE = {"laughs": LAUGHS, "external": EXTERNAL}

#: A one-link SDF robot, with a mesh when {mesh} names one.
SDF = (
    '<sdf version="1.7"><model name="{name}"><link name="ground"/><link name="arm">'
    "<inertial><mass>1</mass><inertia><ixx>1</ixx><iyy>1</iyy><izz>1</izz></inertia>"
    "</inertial>{visual}</link>"
    '<joint name="crank" type="revolute"><parent>ground</parent><child>arm</child>'
    "<axis><xyz>0 0 1</xyz></axis></joint></model></sdf>"
)
#: A one-triangle COLLADA mesh; {doctype} before its root, {name} its geometry's name.
DAE = """<?xml version="1.0" encoding="utf-8"?>
{doctype}<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit name="meter" meter="1"/><up_axis>Z_UP</up_axis></asset>
  <library_geometries><geometry id="tri" name="{name}"><mesh>
    <source id="pos"><float_array id="pos-array" count="9">0 0 0 1 0 0 0 1 0</float_array>
      <technique_common><accessor source="#pos-array" count="3" stride="3">
        <param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/>
      </accessor></technique_common></source>
    <vertices id="vtx"><input semantic="POSITION" source="#pos"/></vertices>
    <triangles count="1"><input semantic="VERTEX" source="#vtx" offset="0"/><p>0 1 2</p></triangles>
  </mesh></geometry></library_geometries>
  <library_visual_scenes><visual_scene id="scene"><node id="n">
    <instance_geometry url="#tri"/></node></visual_scene></library_visual_scenes>
  <scene><instance_visual_scene url="#scene"/></scene>
</COLLADA>
"""


def hostile_copy(path: Path, folder: Path, doctype: str) -> Path:
    """A copy of the robot file ``path`` in ``folder`` with ``doctype`` before its root and
    the root's name (URDF robot, MJCF model) or the SDF model's name made ``&lol9;``."""
    text = path.read_text()
    if text.startswith("<?xml"):
        end = text.index("?>") + 2
        text = text[end:]
    for tag in ("<robot name=", "<mujoco model=", "<model name="):
        if tag in text:
            start = text.index(tag) + len(tag) + 1
            text = text[:start] + "&lol9;" + text[text.index('"', start) :]
            break
    copy = folder / f"hostile{path.suffix}"
    copy.write_text(doctype + text)
    return copy
