#!/usr/bin/env python3
"""Writes a visobjd scene's patch as an MVR with a GDTF fixture type per profile.

An exporter independent of visobjd's own code (only the standard library: tomllib,
zipfile, xml.etree), written from the MVR and GDTF specs (mvrdevelopment/spec): every
[[light]] becomes a <Fixture> (FixtureID and FixtureIDNumeric = channel, the absolute DMX
address (universe - 1) * 512 + address in <Address break="0">), inside a <GroupObject>
named after its group; every profile becomes `visobjd@NAME.gdtf` with one DMX mode,
"Default", whose channels carry the GDTF attributes of the profile's slots. No emitters
are described, so the importer gives them visobjd's default colours, as the built-in
profiles have. A moving light's `pan`/`pan16` and `tilt`/`tilt16` slots become `Pan` and
`Tilt` channels (16-bit: two offsets, coarse then fine) whose channel function runs from
PhysicalFrom = -range/2 to PhysicalTo = +range/2 degrees (the profile's `pan_range` and
`tilt_range`, default 540 and 270), with the DMX centre as the default. The zip entries
carry a fixed date so the same scene gives the same bytes.

usage: export_mvr.py SCENE.toml OUT.mvr
"""

import io
import sys
import tomllib
import uuid
import zipfile
import xml.etree.ElementTree as ET

# docs/scene.md, "Built-in profiles".
BUILT_IN = {
    "dimmer": ["intensity"],
    "dimmer16": ["intensity16"],
    "rgb": ["red", "green", "blue"],
    "irgb": ["intensity", "red", "green", "blue"],
    "rgbw": ["red", "green", "blue", "white"],
    "irgbw": ["intensity", "red", "green", "blue", "white"],
    "rgba": ["red", "green", "blue", "amber"],
}

# GDTF 1.2 Annex A attribute names for visobjd's slots.
ATTRIBUTE = {
    "intensity": "Dimmer",
    "intensity16": "Dimmer",
    "red": "ColorAdd_R",
    "green": "ColorAdd_G",
    "blue": "ColorAdd_B",
    "white": "ColorAdd_W",
    "amber": "ColorAdd_RY",
    "lime": "ColorAdd_GY",
    "uv": "ColorAdd_UV",
    "cyan": "ColorSub_C",
    "magenta": "ColorSub_M",
    "yellow": "ColorSub_Y",
    "pan": "Pan",
    "pan16": "Pan",
    "tilt": "Tilt",
    "tilt16": "Tilt",
}

# docs/scene.md: a profile's full travel in degrees when it does not say.
DEFAULT_RANGE = {"Pan": 540.0, "Tilt": 270.0}

DATE = (2026, 1, 1, 0, 0, 0)
NS = uuid.UUID("6f1c0e7a-3d0b-4a57-9a4e-7a1c5c0de000")


def gdtf(name, profile):
    """description.xml of a one-mode fixture type: `profile` as a [[profile]] table."""
    slots = profile["channels"]
    root = ET.Element("GDTF", DataVersion="1.2")
    ft = ET.SubElement(root, "FixtureType", Name=name, ShortName=name, LongName=name,
                       Manufacturer="visobjd", Description="exported by tests/peers/export_mvr.py",
                       FixtureTypeID=str(uuid.uuid5(NS, "type " + name)).upper(), Thumbnail="",
                       RefFT="", CanHaveChildren="No")
    ET.SubElement(ET.SubElement(ft, "PhysicalDescriptions"), "Emitters")
    geometries = ET.SubElement(ft, "Geometries")
    ET.SubElement(geometries, "Geometry", Name="Body", Model="",
                  Position="{1,0,0,0}{0,1,0,0}{0,0,1,0}{0,0,0,1}")
    modes = ET.SubElement(ft, "DMXModes")
    mode = ET.SubElement(modes, "DMXMode", Name="Default", Geometry="Body")
    channels = ET.SubElement(mode, "DMXChannels")
    offset = 1
    for slot in slots:
        if slot.startswith("fixed:"):
            attribute, width, default = "NoFeature", 1, f"{int(slot[6:])}/1"
        elif slot in ATTRIBUTE:
            attribute = ATTRIBUTE[slot]
            width = 2 if slot.endswith("16") else 1
            default = "0/1"
        else:
            sys.exit(f"export_mvr: slot {slot} of profile {name} has no GDTF attribute here")
        offsets = ",".join(str(offset + i) for i in range(width))
        function = f"Body_{attribute}.{attribute}.{attribute} 1"
        channel = ET.SubElement(channels, "DMXChannel", DMXBreak="1", Offset=offsets,
                                InitialFunction=function, Highlight="None", Geometry="Body")
        logical = ET.SubElement(channel, "LogicalChannel", Attribute=attribute, Snap="No",
                                Master="None", MibFade="0", DMXChangeTimeLimit="0")
        physical = ("0", "1")
        if attribute in DEFAULT_RANGE:
            half = profile.get(attribute.lower() + "_range", DEFAULT_RANGE[attribute]) / 2
            physical = (f"{-half:g}", f"{half:g}")
            default = f"{1 << (8 * width - 1)}/{width}"
        ET.SubElement(logical, "ChannelFunction", Name=f"{attribute} 1", Attribute=attribute,
                      OriginalAttribute="", DMXFrom="0/1", Default=default,
                      PhysicalFrom=physical[0], PhysicalTo=physical[1], RealFade="0",
                      RealAcceleration="0")
        offset += width
    ET.SubElement(mode, "Relations")
    ET.SubElement(mode, "FTMacros")
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def main():
    scene_path, out = sys.argv[1], sys.argv[2]
    with open(scene_path, "rb") as f:
        scene = tomllib.load(f)
    profiles = {name: {"channels": slots} for name, slots in BUILT_IN.items()}
    for p in scene.get("profile", []):
        profiles[p["name"]] = p
    used = sorted({l["profile"] for l in scene["light"]})

    root = ET.Element("GeneralSceneDescription", verMajor="1", verMinor="6")
    ET.SubElement(root, "UserData")
    layers = ET.SubElement(ET.SubElement(root, "Scene"), "Layers")
    layer = ET.SubElement(layers, "Layer", name="visobjd",
                          uuid=str(uuid.uuid5(NS, "layer")).upper())
    top = ET.SubElement(layer, "ChildList")
    groups = {}
    for light in sorted(scene["light"], key=lambda l: l["channel"]):
        parent = top
        group = light.get("group")
        if group is not None:
            if group not in groups:
                g = ET.SubElement(top, "GroupObject", name=group,
                                  uuid=str(uuid.uuid5(NS, "group " + group)).upper())
                groups[group] = ET.SubElement(g, "ChildList")
            parent = groups[group]
        channel = light["channel"]
        fixture = ET.SubElement(parent, "Fixture", name=light.get("name", f"Ch {channel}"),
                                uuid=str(uuid.uuid5(NS, f"fixture {channel}")).upper())
        ET.SubElement(fixture, "Matrix").text = "{1,0,0}{0,1,0}{0,0,1}{0,0,0}"
        ET.SubElement(fixture, "GDTFSpec").text = f"visobjd@{light['profile']}.gdtf"
        ET.SubElement(fixture, "GDTFMode").text = "Default"
        addresses = ET.SubElement(fixture, "Addresses")
        absolute = (light["universe"] - 1) * 512 + light["address"]
        ET.SubElement(addresses, "Address", {"break": "0"}).text = str(absolute)
        ET.SubElement(fixture, "FixtureID").text = str(channel)
        ET.SubElement(fixture, "FixtureIDNumeric").text = str(channel)
        ET.SubElement(fixture, "UnitNumber").text = "0"
    ET.SubElement(root.find("Scene"), "AUXData")

    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        def put(name, data):
            info = zipfile.ZipInfo(name, date_time=DATE)
            info.compress_type = zipfile.ZIP_DEFLATED
            z.writestr(info, data)
        put("GeneralSceneDescription.xml",
            ET.tostring(root, encoding="UTF-8", xml_declaration=True))
        for name in used:
            inner = zipfile.ZipInfo("description.xml", date_time=DATE)
            inner.compress_type = zipfile.ZIP_DEFLATED
            buf = io.BytesIO()
            with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as g:
                g.writestr(inner, gdtf(name, profiles[name]))
            put(f"visobjd@{name}.gdtf", buf.getvalue())


if __name__ == "__main__":
    main()
