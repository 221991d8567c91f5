#!/usr/bin/env python3
"""A fake `gphoto2` for tests: an independent peer of visobjd's camera layer.

It answers the options visobjd uses the way gphoto2 2.5 documents them:
  --auto-detect                      a `Model`/`Port` table: header, dashed line, rows
  --get-config KEY                   Label:, Readonly:, Type:, Current:, Choice: N VALUE, END
  --set-config KEY=VALUE             exit 1 with `*** Error (-2: 'Bad parameters') ***`
                                     for a value not among the choices
  --capture-image-and-download       one file per image format, named by --filename
  --filename PATTERN                 %C suffix (JPG, DNG), %f camera name, %n number, %%
  --force-overwrite                  without it, an existing file prompts on stdin
Options may be combined; the settings options apply to every action, and the actions
run in the order given, as in gphoto2.

Environment:
  FAKE_GPHOTO2_STATE     (required) JSON file with the camera state (created if missing)
  FAKE_GPHOTO2_LOG       a file to which each call's argv is appended, one line per call
  FAKE_GPHOTO2_SCENE     a .npy float32 HxWx3 linear radiance array (default: a gradient)
  FAKE_GPHOTO2_APERTURE_KEY  `f-number` for a body that names it so (values `f/8`)
  FAKE_GPHOTO2_REFUSE    KEY=VALUE[,KEY=VALUE]: listed among the choices, refused by set
  FAKE_GPHOTO2_HANG_CAPTURE  N[,M]: the Nth capture (from 1) sleeps FAKE_GPHOTO2_HANG_S
                         seconds (default 3600) instead of answering; an entry `lit:K`
                         (with a rig) hangs every capture whose DMX lights rig light K
                         (from 1) alone, so a retry, seeing the same DMX, hangs too
  FAKE_GPHOTO2_FAIL_CALL N[,M] or `all`: the Nth call (from 1) fails with -53
  FAKE_GPHOTO2_NO_CAMERA 1: no camera is connected
  FAKE_GPHOTO2_SACN_PORT with FAKE_GPHOTO2_RIG: render from the DMX on the wire. Each
                         capture binds 127.0.0.1:PORT, collects E1.31 data packets until it
                         has one of every universe the rig uses (at most ~1 s), takes each
                         light's level from its slots (rig_levels) and renders
                         sum(level x basis) instead of FAKE_GPHOTO2_SCENE
  FAKE_GPHOTO2_RIG       JSON list of lights: {"universe", "address", "footprint",
                         "basis", optional "intensity"} with basis a .npy float32 HxWx3
                         linear image (a relative path is taken from the JSON file's
                         folder) and intensity the offset of an intensity slot in the
                         footprint (an irgb fixture: 0); a moving light adds "pan" and
                         "tilt" (offsets of its 16-bit pan and tilt, coarse byte first),
                         "pan_range" and "tilt_range" (degrees of full travel, DMX centre
                         0 degrees) and "positions", a list of {"pan", "tilt", "basis"}:
                         it is rendered with the basis of the position whose pan and tilt
                         the wire's 16-bit values match within one step (65535ths of the
                         range), and black when none does
  FAKE_GPHOTO2_MOTION    with FAKE_GPHOTO2_MOVE_S: a JSON file a test's listener keeps of
                         the DMX on the wire, {"UNIVERSE": [[unix seconds, hex of 512
                         slots], ...]}, each state with the time it was first seen, oldest
                         first: a moving light whose pan and tilt last changed less than
                         FAKE_GPHOTO2_MOVE_S seconds ago is still on its way and is
                         rendered where it was before (rig_aims)
  FAKE_GPHOTO2_ZOOM      N: every rig pixel becomes NxN sensor pixels (default 1)
  FAKE_GPHOTO2_SEED      seed of the rig render's noise (default 1; each capture adds its
                         number), shot noise of 20,000 electrons at full scale
  FAKE_GPHOTO2_DMX_LOG   a file to which each rig render appends a JSON line: capture
                         number, each universe's 512 slots as hex, each light's level
  FAKE_GPHOTO2_BODY      `second`: a body built differently from the first in every
                         step that turns light into a file (below)
  FAKE_GPHOTO2_RAW_DECLARES  WxH: each DNG's main IFD declares W x H pixels over its
                         real (small) data, as a broken or hostile file does

Each frame is rendered (render_frame) from the scene scaled by the exposure through a
simple camera response with clipping, and written as a JPEG whose EXIF holds the
exposure the shutter really gave: the true 1/3-stop time (1/64 s for `1/60`), not the
rounded label, as a rational ExposureTime; ISOSpeedRatings; FNumber. With the image
format set to RAW the frame is written as a DNG instead (write_dng: PiDNG, a Bayer mosaic
of the camera's own RGB with its colour matrix).

The second body (FAKE_GPHOTO2_BODY=second, a "Nikon Z 6_2") shares only the gphoto2
command line with the first; its pipeline is its own, so that capture is measured on a
camera it was not tuned on (class SecondBody):
  exposure   the shutter gives the EXIF time (the 1/3-stop time) times 1 + u, u uniform in
             +-2% and new for every shot (seeded by FAKE_GPHOTO2_SEED and the capture's
             number): EXIF is never exactly right, and never the same error twice
  sensor     its own camera RGB (rows unlike the first body's), 1.0 radiance at 1/64 s,
             ISO 100, f/8 lands at 12% of full scale; 9,000 electrons at full scale at ISO
             100 (fewer at higher ISO) with shot noise, 4.5 electrons of read noise, a fixed
             pattern of 0.5% gain (PRNU) and 1 electron of offset (DSNU) per pixel, the
             same in every frame (the sensor's own, seeded once)
  JPEG       the noisy camera RGB back to sRGB through the inverse of its matrix (the
             noise correlated across channels, as in-camera processing makes it), a black
             cut at 0.15% of full scale, a log encoding log(1 + 48 x) / log(49), then an
             S-curve (powers 1.4 below and above a pivot at 0.42: a toe, and a shoulder
             whose slope falls to 0 at full scale), the same curve on each channel, 8 bits,
             encoded at quality 90 with 4:2:0 chroma subsampling
  raw        a GRBG mosaic of the camera RGB, 14 bits with a black level per colour of the
             2x2 block (1022, 1024, 1025, 1023: BlackLevelRepeatDim) and white level 15520;
             noise below black is kept (clipped at 0 DN), as a sensor reads it
"""

import json
import os
import struct
import sys
import time
from fractions import Fraction

SHUTTERS = ["bulb", "30", "25", "20", "15", "13", "10", "8", "6", "5", "4", "3.2", "2.5",
            "2", "1.6", "1.3", "1", "0.8", "0.6", "0.5", "0.4", "0.3", "1/4", "1/5", "1/6",
            "1/8", "1/10", "1/13", "1/15", "1/20", "1/25", "1/30", "1/40", "1/50", "1/60",
            "1/80", "1/100", "1/125", "1/160", "1/200", "1/250", "1/320", "1/400", "1/500",
            "1/640", "1/800", "1/1000", "1/1250", "1/1600", "1/2000", "1/2500", "1/3200",
            "1/4000"]
BODY = os.environ.get("FAKE_GPHOTO2_BODY", "first")
ISOS = ["Auto", "100", "200", "400", "800", "1600", "3200", "6400"]
APERTURES = ["4", "5.6", "8", "11", "16"]
FORMATS = ["Large Fine JPEG", "RAW", "RAW + Large Fine JPEG"]


def radio(label, current, choices):
    return {"label": label, "readonly": 0, "type": "RADIO", "current": current,
            "choices": choices}


def default_state():
    aperture_key = os.environ.get("FAKE_GPHOTO2_APERTURE_KEY", "aperture")
    if aperture_key == "f-number":
        aperture = radio("F-Number", "f/8", ["f/" + a for a in APERTURES])
    else:
        aperture = radio("Aperture", "8", list(APERTURES))
    second = BODY == "second"
    return {
        "model": "Nikon Z 6_2" if second else "Canon EOS 6D",
        "port": "usb:002,004" if second else "usb:001,007",
        "calls": 0,
        "captures": 0,
        "image_number": 0,
        "config": {
            "shutterspeed": radio("Shutter Speed", "1/60", list(SHUTTERS)),
            "iso": radio("ISO Speed", "100", list(ISOS)),
            aperture_key: aperture,
            "imageformat": radio("Image Format", "Large Fine JPEG", list(FORMATS)),
        },
    }


def load_state(path):
    try:
        with open(path, encoding="utf-8") as f:
            return json.load(f)
    except FileNotFoundError:
        return default_state()


def save_state(path, state):
    tmp = path + ".tmp"
    with open(tmp, "w", encoding="utf-8") as f:
        json.dump(state, f, indent=1)
    os.replace(tmp, path)


def numbers(name):
    """The call numbers an N[,M] variable names; `all` is every call."""
    text = os.environ.get(name, "").strip()
    if text == "all":
        return "all"
    return {int(n) for n in text.split(",") if n.strip() and ":" not in n}


def hit(spec, n):
    return spec == "all" or n in spec


def error(code, text, context=None):
    """Prints gphoto2's error lines (a context message first, if any) and exits 1."""
    if context:
        sys.stderr.write("\n*** Error ***              \n%s\n" % context)
    sys.stderr.write("*** Error (%d: '%s') ***       \n\n" % (code, text))
    sys.stdout.write("For debugging messages, please use the --debug option.\n")
    sys.exit(1)


def seconds(label):
    if "/" in label:
        n, d = label.split("/", 1)
        return float(n) / float(d)
    return float(label)


def true_time(label):
    """What the shutter gives for a label: the exact 1/3-stop time 2^(k/3) s."""
    import math
    k = round(3 * math.log2(seconds(label)))
    return Fraction(2.0 ** (k / 3.0)).limit_denominator(100000)


def default_scene():
    import numpy as np
    h, w = 32, 48
    x = np.linspace(0.0, 1.0, w, dtype=np.float32)
    y = np.linspace(0.0, 1.0, h, dtype=np.float32)
    scene = np.zeros((h, w, 3), dtype=np.float32)
    ramp = np.outer(np.ones(h, dtype=np.float32), 10.0 ** (x * 4 - 2))  # 0.01 .. 100
    scene[..., 0] = ramp
    scene[..., 1] = ramp * (0.5 + 0.5 * y[:, None])
    scene[..., 2] = ramp * 0.25
    return scene


def sensor_signal(radiance, exposure_s, iso, f_number, noise=None):
    """Linear radiance times the exposure (time, ISO, aperture) as a fraction of full
    scale; with `noise` (a numpy Generator), shot and read noise."""
    import numpy as np
    # 1.0 radiance at 1/64 s, ISO 100, f/8 lands at 18% grey.
    gain = 0.18 * 64.0 * 64.0
    signal = radiance * (exposure_s * (iso / 100.0) / (f_number * f_number) * gain)
    if noise is not None:
        # Shot noise (20,000 electrons at full scale) and a little read noise.
        electrons = 20000.0
        sigma = np.sqrt(np.clip(signal, 0.0, 1.0) / electrons + (2.0 / electrons) ** 2)
        signal = signal + noise.standard_normal(signal.shape).astype(np.float32) * sigma
    return signal


def render_frame(signal):
    """The JPEG's pixels: the sensor signal through a gamma response, clipped to 8 bits."""
    import numpy as np
    encoded = np.clip(signal, 0.0, 1.0) ** (1.0 / 2.2)
    return np.round(encoded * 255.0).astype(np.uint8)


# The raw file: the camera's own RGB (its filters pass some of each other's light; rows:
# camera R, G, B from linear sRGB) on an RGGB Bayer mosaic, 14 bits over a black level.
CAMERA_RGB = [[0.75, 0.20, 0.05], [0.12, 0.76, 0.12], [0.03, 0.22, 0.75]]
RAW_BLACK, RAW_WHITE = 600, 15000
# IEC 61966-2-1: linear sRGB (D65) to CIE XYZ.
SRGB_TO_XYZ = [[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]]


def declare_size(name, size):
    """Makes the DNG at `name` declare `size` (WxH) in its main IFD's ImageWidth and
    ImageLength (as LONGs), its data left as it is."""
    w, h = (int(v) for v in size.split("x"))
    with open(name, "r+b") as f:
        data = bytearray(f.read())
        endian = "<" if data[:2] == b"II" else ">"
        ifd = struct.unpack(endian + "I", data[4:8])[0]
        count = struct.unpack(endian + "H", data[ifd:ifd + 2])[0]
        for e in range(ifd + 2, ifd + 2 + 12 * count, 12):
            tag = struct.unpack(endian + "H", data[e:e + 2])[0]
            if tag in (256, 257):
                data[e + 2:e + 12] = struct.pack(endian + "HII", 4, 1, w if tag == 256 else h)
        f.seek(0)
        f.write(data)


def mosaic_of(camera, pattern):
    """The 2x2 Bayer mosaic of camera RGB (HxWx3) for `pattern` (e.g. "RGGB": the colours
    of the block's top-left, top-right, bottom-left and bottom-right samples), cut to even
    dimensions."""
    import numpy as np
    h, w = camera.shape[0] // 2 * 2, camera.shape[1] // 2 * 2
    mosaic = np.empty((h, w), dtype=np.float64)
    for k, colour in enumerate(pattern):
        dy, dx = divmod(k, 2)
        c = "RGB".index(colour)
        mosaic[dy::2, dx::2] = camera[dy:h:2, dx:w:2, c]
    return mosaic


def write_dng(name, raw, pattern, black, white, cam, exposure, iso, f_number, state):
    """An uncompressed 16-bit Bayer DNG written by PiDNG (an independent DNG writer), as
    a DNG-recording body makes one: the mosaic `raw` (uint16 HxW) with its CFA `pattern`,
    BlackLevel (one value, or four repeating over the 2x2 block), WhiteLevel,
    ColorMatrix1 (XYZ to camera, D65, from `cam`, the camera's RGB from linear sRGB) and
    the exposure as TIFF-context tags in the main IFD (PiDNG writes no EXIF sub-IFD)."""
    import numpy as np
    from pidng.core import RAW2DNG, DNGTags, Tag
    from pidng.defs import (CFAPattern, CalibrationIlluminant, DNGVersion, Orientation,
                            PhotometricInterpretation)
    xyz_to_cam = np.array(cam, dtype=np.float64) @ np.linalg.inv(np.array(SRGB_TO_XYZ))
    ccm = [[int(round(v * 10000)), 10000] for v in xyz_to_cam.flatten()]
    fnum = Fraction(f_number).limit_denominator(100)
    h, w = raw.shape
    t = DNGTags()
    t.set(Tag.ImageWidth, w)
    t.set(Tag.ImageLength, h)
    t.set(Tag.TileWidth, w)
    t.set(Tag.TileLength, h)
    t.set(Tag.Orientation, Orientation.Horizontal)
    t.set(Tag.PhotometricInterpretation, PhotometricInterpretation.Color_Filter_Array)
    t.set(Tag.SamplesPerPixel, 1)
    t.set(Tag.BitsPerSample, 16)
    t.set(Tag.CFARepeatPatternDim, [2, 2])
    t.set(Tag.CFAPattern, getattr(CFAPattern, pattern))
    if isinstance(black, (list, tuple)):
        t.set(Tag.BlackLevelRepeatDim, [2, 2])
    t.set(Tag.BlackLevel, black)
    t.set(Tag.WhiteLevel, white)
    t.set(Tag.ColorMatrix1, ccm)
    t.set(Tag.CalibrationIlluminant1, CalibrationIlluminant.D65)
    t.set(Tag.AsShotNeutral, [[1, 1], [1, 1], [1, 1]])
    t.set(Tag.Make, state["model"].split()[0])
    t.set(Tag.Model, state["model"])
    t.set(Tag.UniqueCameraModel, state["model"])
    t.set(Tag.DNGVersion, DNGVersion.V1_4)
    t.set(Tag.ExposureTime, [[exposure.numerator, exposure.denominator]])
    t.set(Tag.FNumber, [[fnum.numerator, fnum.denominator]])
    t.set(Tag.PhotographicSensitivity, [iso])
    writer = RAW2DNG()
    writer.options(t, path="", compress=False)
    with open(name, "wb") as f:
        f.write(writer.convert(raw))


class FirstBody:
    """The first body: sensor_signal and render_frame above, JPEG at quality 95 (4:4:4 as
    Pillow writes at that quality), an RGGB DNG over one black level."""
    jpeg_options = {"quality": 95}

    @staticmethod
    def expose(radiance, exposure, iso, f_number, seed):
        import numpy as np
        noise = np.random.default_rng(seed) if seed is not None else None
        return sensor_signal(radiance, float(exposure), iso, f_number, noise)

    @staticmethod
    def jpeg(signal):
        return render_frame(signal)

    @staticmethod
    def dng(name, signal, exposure, iso, f_number, state):
        import numpy as np
        cam = np.array(CAMERA_RGB, dtype=np.float64)
        camera = np.clip(signal.astype(np.float64), 0.0, None) @ cam.T
        mosaic = mosaic_of(camera, "RGGB")
        raw = np.clip(np.round(RAW_BLACK + np.clip(mosaic, 0.0, 1.0) * (RAW_WHITE - RAW_BLACK)),
                      0, RAW_WHITE).astype(np.uint16)
        write_dng(name, raw, "RGGB", RAW_BLACK, RAW_WHITE, CAMERA_RGB, exposure, iso, f_number,
                  state)


class SecondBody:
    """The second body (FAKE_GPHOTO2_BODY=second, see the module's documentation): its own
    exposure error, sensor, noise, JPEG tone curve and encoding, and raw levels. What
    `expose` returns is the sensor's camera RGB as a fraction of full scale."""
    # Rows: camera R, G, B from linear sRGB (unlike the first body's and the sim's).
    CAMERA_RGB = [[0.62, 0.33, 0.05], [0.08, 0.82, 0.10], [0.02, 0.24, 0.74]]
    GAIN = 0.12 * 64.0 * 64.0  # 1.0 radiance at 1/64 s, ISO 100, f/8: 12% of full scale
    FULL_WELL = 9000.0  # electrons at full scale, ISO 100
    READ_NOISE = 4.5  # electrons
    PRNU = 0.005  # fixed per-pixel gain spread
    DSNU = 1.0  # fixed per-pixel offset spread, electrons
    EXPOSURE_ERROR = 0.02  # the shutter's time is EXIF's times 1 + U(-2%, +2%)
    BLACK_CUT = 0.0015
    LOG_A = 48.0
    PIVOT = 0.42
    CONTRAST = 1.4
    RAW_BLACK = [1022, 1024, 1025, 1023]  # per sample of the 2x2 block
    RAW_WHITE = 15520
    PATTERN = "GRBG"
    jpeg_options = {"quality": 90, "subsampling": 2}  # 2: 4:2:0

    @classmethod
    def expose(cls, radiance, exposure, iso, f_number, seed):
        """The noisy camera RGB of `radiance` (linear sRGB) for the EXIF `exposure`: the
        shutter's true time is off by up to 2%, new each shot."""
        import numpy as np
        seed = 1 if seed is None else seed
        actual = float(exposure) * (1.0 + np.random.default_rng([seed, 2]).uniform(
            -cls.EXPOSURE_ERROR, cls.EXPOSURE_ERROR))
        cam = np.array(cls.CAMERA_RGB, dtype=np.float64)
        camera = radiance.astype(np.float64) @ cam.T
        camera *= actual * (iso / 100.0) / (f_number * f_number) * cls.GAIN
        electrons = cls.FULL_WELL * 100.0 / iso
        fixed = np.random.default_rng(20240611)  # the sensor's own patterns
        prnu = 1.0 + cls.PRNU * fixed.standard_normal(camera.shape)
        dsnu = cls.DSNU * fixed.standard_normal(camera.shape)
        noise = np.random.default_rng([seed, 1])
        e = np.clip(camera * prnu, 0.0, None) * electrons
        e = (e + np.sqrt(e) * noise.standard_normal(e.shape)
             + cls.READ_NOISE * noise.standard_normal(e.shape) + dsnu)
        return e / electrons

    @classmethod
    def tone(cls, x):
        """The tone curve, linear (full scale 1) to 0..1, applied to each channel alike (a
        neutral stays neutral at every level, as in a camera's JPEG): a black cut, a log
        encoding, an S-curve about PIVOT."""
        import numpy as np
        x = np.clip((x - cls.BLACK_CUT) / (1.0 - cls.BLACK_CUT), 0.0, 1.0)
        y = np.log1p(cls.LOG_A * x) / np.log1p(cls.LOG_A)
        k, p = cls.CONTRAST, cls.PIVOT
        low = p * (np.minimum(y, p) / p) ** k
        high = 1.0 - (1.0 - p) * ((1.0 - np.maximum(y, p)) / (1.0 - p)) ** k
        return np.where(y < p, low, high)

    @classmethod
    def jpeg(cls, camera):
        import numpy as np
        srgb = camera @ np.linalg.inv(np.array(cls.CAMERA_RGB, dtype=np.float64)).T
        return np.round(cls.tone(srgb) * 255.0).astype(np.uint8)

    @classmethod
    def dng(cls, name, camera, exposure, iso, f_number, state):
        import numpy as np
        mosaic = mosaic_of(camera, cls.PATTERN)
        black = np.empty(mosaic.shape)
        for k, b in enumerate(cls.RAW_BLACK):
            dy, dx = divmod(k, 2)
            black[dy::2, dx::2] = b
        span = cls.RAW_WHITE - max(cls.RAW_BLACK)
        raw = np.clip(np.round(black + mosaic * span), 0, cls.RAW_WHITE).astype(np.uint16)
        write_dng(name, raw, cls.PATTERN, cls.RAW_BLACK, cls.RAW_WHITE, cls.CAMERA_RGB,
                  exposure, iso, f_number, state)


def body():
    return SecondBody if BODY == "second" else FirstBody


def parse_sacn(p):
    """(universe, 512 slots) of an E1.31 data packet carrying DMX, from the standard's
    octets (E1.31-2018 Table 4-1); None for anything else, for a stream being terminated
    (Options bit 6) and for a non-zero start code."""
    if len(p) < 126 or p[4:16] != b"ASC-E1.17\0\0\0":
        return None
    if p[18:22] != b"\0\0\0\x04" or p[40:44] != b"\0\0\0\x02" or p[117] != 0x02:
        return None  # root VECTOR_ROOT_E131_DATA, framing VECTOR_E131_DATA_PACKET, DMP set
    if p[112] & 0x40:
        return None  # Stream_Terminated
    universe = (p[113] << 8) | p[114]
    count = (p[123] << 8) | p[124]  # property values, the start code first
    values = p[125:125 + count]
    if count < 1 or len(values) < count or values[0] != 0:
        return None
    dmx = bytearray(512)
    dmx[:count - 1] = values[1:513]
    return universe, bytes(dmx)


def receive_dmx(port, universes, wait_s=1.0):
    """The latest DMX of each universe seen on 127.0.0.1:port within `wait_s`, returning as
    soon as every universe in `universes` has a packet."""
    import socket
    got = {}
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind(("127.0.0.1", port))
    deadline = time.monotonic() + wait_s
    try:
        while not universes <= got.keys():
            left = deadline - time.monotonic()
            if left <= 0:
                break
            sock.settimeout(left)
            try:
                packet = sock.recv(2048)
            except socket.timeout:
                break
            parsed = parse_sacn(packet)
            if parsed:
                got[parsed[0]] = parsed[1]
    finally:
        sock.close()
    return got


def load_rig(path):
    with open(path, encoding="utf-8") as f:
        rig = json.load(f)
    base = os.path.dirname(os.path.abspath(path))
    for light in rig:
        for entry in [light] + light.get("positions", []):
            if "basis" in entry:
                entry["basis"] = os.path.join(base, entry["basis"])
    return rig


def position_slots(light):
    """The footprint offsets of a moving light's 16-bit pan and tilt (coarse and fine of
    each); none for a fixed light."""
    if "positions" not in light:
        return set()
    return {light["pan"], light["pan"] + 1, light["tilt"], light["tilt"] + 1}


def rig_levels(rig, dmx):
    """Each light's level: the max of its slots / 255, or, for a light with an intensity
    slot, that slot / 255 times the max of its other slots / 255 (1 when it has none): a
    fixture at intensity 0 is dark whatever colour it holds. A moving light's pan and tilt
    are not light. 0 when its universe was not seen."""
    levels = []
    for light in rig:
        slots = dmx.get(light["universe"], bytes(512))
        start = light["address"] - 1
        aim = position_slots(light)
        slots = list(slots[start:start + light["footprint"]])
        i = light.get("intensity")
        if i is None:
            levels.append(max((v for k, v in enumerate(slots) if k not in aim), default=0)
                          / 255.0)
        else:
            others = [v for k, v in enumerate(slots) if k != i and k not in aim]
            levels.append(slots[i] / 255.0 * (max(others) / 255.0 if others else 1.0))
    return levels


def degrees(slots, offset, travel):
    """The degrees from centre of the 16-bit value at `offset` (coarse, fine) through a
    travel of `travel` degrees, and one 16-bit step in degrees."""
    word = slots[offset] * 256 + slots[offset + 1]
    return (word / 65535.0 - 0.5) * travel, travel / 65535.0


def aim_of(light, dmx):
    """The index of the position a moving light's 16-bit pan and tilt in `dmx` (one
    universe's 512 slots) point it at, within one step; None when none matches."""
    slots = dmx[light["address"] - 1:]
    pan, pan_step = degrees(slots, light["pan"], light["pan_range"])
    tilt, tilt_step = degrees(slots, light["tilt"], light["tilt_range"])
    for k, p in enumerate(light["positions"]):
        if abs(pan - p["pan"]) <= pan_step and abs(tilt - p["tilt"]) <= tilt_step:
            return k
    return None


def motion_history():
    """The DMX states a test's listener saw ({universe: [(time, 512 bytes)]}), or None
    without FAKE_GPHOTO2_MOTION."""
    path = os.environ.get("FAKE_GPHOTO2_MOTION")
    if not path:
        return None
    try:
        with open(path, encoding="utf-8") as f:
            seen = json.load(f)
    except FileNotFoundError:
        return {}
    return {int(u): [(t, bytes.fromhex(h)) for t, h in states] for u, states in seen.items()}


def rig_aims(rig, dmx):
    """Per light, the index of the position it is rendered at (None: black, or a fixed
    light). A moving light takes FAKE_GPHOTO2_MOVE_S seconds to reach the pan and tilt it
    is sent: while the listener's history (FAKE_GPHOTO2_MOTION) shows them first sent less
    than that ago, it is still where the state before them pointed it."""
    history = motion_history()
    move_s = float(os.environ.get("FAKE_GPHOTO2_MOVE_S", "0"))
    now = time.time()
    aims = []
    for light in rig:
        if "positions" not in light:
            aims.append(None)
            continue
        slots = dmx.get(light["universe"], bytes(512))
        states = (history or {}).get(light["universe"], [])
        start = light["address"] - 1
        aim = [start + k for k in sorted(position_slots(light))]
        current = [slots[k] for k in aim]
        # The last state whose pan and tilt differ from the wire's: the mover left it
        # when the next state was first seen.
        for i in range(len(states) - 1, -1, -1):
            if [states[i][1][k] for k in aim] != current:
                if i + 1 < len(states) and now - states[i + 1][0] < move_s:
                    slots = states[i][1]
                break
        aims.append(aim_of(light, slots))
    return aims


def rig_radiance(rig, levels, aims):
    import numpy as np
    total = None
    for light, level, aim in zip(rig, levels, aims):
        if "positions" in light:
            basis = np.load(light["positions"][aim or 0]["basis"]).astype(np.float32)
            if aim is None:
                basis = np.zeros_like(basis)  # aimed at none of its positions: out of frame
        else:
            basis = np.load(light["basis"]).astype(np.float32)
        total = basis * level if total is None else total + basis * level
    zoom = int(os.environ.get("FAKE_GPHOTO2_ZOOM", "1"))
    if zoom > 1:
        total = np.repeat(np.repeat(total, zoom, axis=0), zoom, axis=1)
    return total


def exif_bytes(state, exposure, iso, f_number):
    import piexif
    fnum = Fraction(f_number).limit_denominator(100)
    return piexif.dump({
        "0th": {
            piexif.ImageIFD.Make: state["model"].split()[0].encode(),
            piexif.ImageIFD.Model: state["model"].encode(),
        },
        "Exif": {
            piexif.ExifIFD.ExposureTime: (exposure.numerator, exposure.denominator),
            piexif.ExifIFD.ISOSpeedRatings: iso,
            piexif.ExifIFD.FNumber: (fnum.numerator, fnum.denominator),
            piexif.ExifIFD.DateTimeOriginal: time.strftime("%Y:%m:%d %H:%M:%S").encode(),
        },
    })


def expand(pattern, suffix, stem, number):
    out, i = [], 0
    while i < len(pattern):
        c = pattern[i]
        if c == "%" and i + 1 < len(pattern):
            code = pattern[i + 1]
            out.append({"C": suffix, "f": stem, "n": "%d" % number, "%": "%"}.get(code, "%" + code))
            i += 2
        else:
            out.append(c)
            i += 1
    return "".join(out)


def rig_frame(state):
    """With FAKE_GPHOTO2_SACN_PORT and FAKE_GPHOTO2_RIG: (radiance from the DMX on the wire,
    the rig's light levels); else None."""
    port = os.environ.get("FAKE_GPHOTO2_SACN_PORT")
    rig_path = os.environ.get("FAKE_GPHOTO2_RIG")
    if not (port and rig_path):
        return None
    rig = load_rig(rig_path)
    dmx = receive_dmx(int(port), {light["universe"] for light in rig})
    levels = rig_levels(rig, dmx)
    aims = rig_aims(rig, dmx)
    log = os.environ.get("FAKE_GPHOTO2_DMX_LOG")
    if log:
        with open(log, "a", encoding="utf-8") as f:
            f.write(json.dumps({
                "capture": state["captures"],
                "universes": {str(u): d.hex() for u, d in sorted(dmx.items())},
                "levels": levels,
                "aims": aims,
                "time": time.time(),
            }) + "\n")
    return rig_radiance(rig, levels, aims), levels


def hangs_when_lit(levels):
    """Whether FAKE_GPHOTO2_HANG_CAPTURE has `lit:K` and rig light K alone is lit."""
    for entry in os.environ.get("FAKE_GPHOTO2_HANG_CAPTURE", "").split(","):
        entry = entry.strip()
        if entry.startswith("lit:"):
            k = int(entry[4:]) - 1
            if levels[k] > 0 and all(v == 0 for i, v in enumerate(levels) if i != k):
                return True
    return False


def hang():
    sys.stdout.flush()
    time.sleep(float(os.environ.get("FAKE_GPHOTO2_HANG_S", "3600")))


def capture(state, filename, force):
    from PIL import Image
    import numpy as np

    config = state["config"]
    label = config["shutterspeed"]["current"]
    if label == "bulb":
        error(-1, "Unspecified error", "Bulb needs --bulb or --set-config eosremoterelease.")
    exposure = true_time(label)
    iso_text = config["iso"]["current"]
    iso = 100 if iso_text == "Auto" else int(iso_text)
    aperture = config.get("aperture") or config.get("f-number")
    f_number = float(aperture["current"].replace("f/", ""))

    cam = body()
    from_rig = rig_frame(state)
    seed = int(os.environ.get("FAKE_GPHOTO2_SEED", "1")) + state["captures"]
    if from_rig:
        radiance, levels = from_rig
        if hangs_when_lit(levels):
            hang()
    else:
        scene_path = os.environ.get("FAKE_GPHOTO2_SCENE")
        radiance = np.load(scene_path).astype(np.float32) if scene_path else default_scene()
        if cam is FirstBody:
            seed = None  # the first body renders a scene without noise
    signal = cam.expose(radiance, exposure, iso, f_number, seed)
    image = Image.fromarray(cam.jpeg(signal), "RGB")
    exif = exif_bytes(state, exposure, iso, f_number)

    fmt = config["imageformat"]["current"]
    suffixes = (["DNG"] if "RAW" in fmt else []) + (["JPG"] if "JPEG" in fmt else [])
    state["image_number"] += 1
    stem = "IMG_%04d" % state["image_number"]
    for suffix in suffixes:
        on_camera = "/store_00020001/DCIM/100CANON/%s.%s" % (stem, suffix)
        print("New file is in location %s on the camera" % on_camera)
        name = expand(filename, suffix, stem, state["image_number"]) if filename else stem + "." + suffix
        if os.path.exists(name) and not force:
            sys.stdout.write("File %s exists. Overwrite? [y|n] " % name)
            sys.stdout.flush()
            if not sys.stdin.readline().strip().lower().startswith("y"):
                continue
        print("Saving file as %s" % name)
        if suffix == "JPG":
            image.save(name, "JPEG", exif=exif, **cam.jpeg_options)
        else:
            cam.dng(name, signal, exposure, iso, f_number, state)
            if os.environ.get("FAKE_GPHOTO2_RAW_DECLARES"):
                declare_size(name, os.environ["FAKE_GPHOTO2_RAW_DECLARES"])
        print("Deleting file %s on the camera" % on_camera)


def main(argv):
    state_path = os.environ.get("FAKE_GPHOTO2_STATE")
    if not state_path:
        sys.stderr.write("fake gphoto2: set FAKE_GPHOTO2_STATE to a JSON state file\n")
        return 2
    log = os.environ.get("FAKE_GPHOTO2_LOG")
    if log:
        with open(log, "a", encoding="utf-8") as f:
            f.write(json.dumps(argv) + "\n")

    state = load_state(state_path)
    state["calls"] += 1
    save_state(state_path, state)

    # First pass: settings that apply to every action. Second: actions, in order.
    actions, filename, force, i = [], None, False, 0
    while i < len(argv):
        arg = argv[i]
        key, eq, inline = arg.partition("=")
        takes = key in ("--get-config", "--set-config", "--filename")
        if takes:
            if eq:
                value = inline
            elif i + 1 < len(argv):
                i += 1
                value = argv[i]
            else:
                sys.stderr.write("%s: missing argument\n" % key)
                return 1
        if key == "--filename":
            filename = value
        elif key == "--force-overwrite":
            force = True
        elif key in ("--get-config", "--set-config"):
            actions.append((key, value))
        elif key in ("--auto-detect", "--capture-image-and-download"):
            actions.append((key, None))
        else:
            sys.stderr.write("gphoto2: unknown option %s\n" % arg)
            return 1
        i += 1

    if hit(numbers("FAKE_GPHOTO2_FAIL_CALL"), state["calls"]):
        error(-53, "Could not claim the USB device",
              "Could not claim interface 0 (Device or resource busy). Make sure no other "
              "program (gvfs-gphoto2-volume-monitor) or kernel module (such as sdc2xx, "
              "stv680, spca50x) is using the device and you have read/write access to the "
              "device.")
    no_camera = os.environ.get("FAKE_GPHOTO2_NO_CAMERA") == "1"

    for action, value in actions:
        if action == "--auto-detect":
            print("%-30s %s" % ("Model", "Port"))
            print("-" * 58)
            if not no_camera:
                print("%-30s %s" % (state["model"], state["port"]))
            continue
        if no_camera:
            sys.stderr.write("*** Error: No camera found. ***\n\n")
            return 1
        config = state["config"]
        if action == "--get-config":
            entry = config.get(value)
            if entry is None:
                error(-2, "Bad parameters", "%s not found in configuration tree." % value)
            print("Label: %s" % entry["label"])
            print("Readonly: %d" % entry["readonly"])
            print("Type: %s" % entry["type"])
            print("Current: %s" % entry["current"])
            for n, choice in enumerate(entry["choices"]):
                print("Choice: %d %s" % (n, choice))
            print("END")
        elif action == "--set-config":
            key, _, new = value.partition("=")
            entry = config.get(key)
            if entry is None:
                error(-2, "Bad parameters", "%s not found in configuration tree." % key)
            refused = {r.strip() for r in os.environ.get("FAKE_GPHOTO2_REFUSE", "").split(",") if r.strip()}
            if new not in entry["choices"]:
                error(-2, "Bad parameters", "Choice %s not found within list of choices." % new)
            if "%s=%s" % (key, new) in refused:
                error(-2, "Bad parameters", "Failed to set new configuration value %s for configuration entry %s." % (new, key))
            entry["current"] = new
            save_state(state_path, state)
        elif action == "--capture-image-and-download":
            state["captures"] += 1
            save_state(state_path, state)
            if hit(numbers("FAKE_GPHOTO2_HANG_CAPTURE"), state["captures"]):
                hang()
            capture(state, filename, force)
            save_state(state_path, state)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
