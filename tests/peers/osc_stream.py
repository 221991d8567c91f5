"""What the fake consoles share (tests/peers/fake_eos.py, fake_eos_console.py,
fake_ma3.py): OSC messages built with python-osc, OSC over TCP framed as OSC 1.0 (a
32-bit length prefix) or OSC 1.1 (SLIP, RFC 1055), written here from those specifications,
a console's channel selection (1 Thru 4 + 7), and Eos's focus palettes as its OSC
answers them."""

import struct

from pythonosc.osc_message_builder import OscMessageBuilder

END, ESC, ESC_END, ESC_ESC = 0xC0, 0xDB, 0xDC, 0xDD


def build(address, args):
    """An OSC message: ints as int32, everything else as strings."""
    b = OscMessageBuilder(address=address)
    for a in args:
        b.add_arg(a, "i" if isinstance(a, int) else "s")
    return b.build().dgram


def framed(dgram, slip):
    """One packet framed for a TCP stream."""
    if not slip:
        return struct.pack(">I", len(dgram)) + dgram
    body = bytearray([END])
    for b in dgram:
        body += {END: bytes([ESC, ESC_END]), ESC: bytes([ESC, ESC_ESC])}.get(b, bytes([b]))
    body.append(END)
    return bytes(body)


def frames(conn, slip):
    """The packets a TCP client sends, one at a time, until it closes."""
    buf = b""
    while True:
        data = conn.recv(65536)
        if not data:
            return
        buf += data
        if slip:
            while bytes([END]) in buf:
                frame, buf = buf.split(bytes([END]), 1)
                frame = frame.replace(bytes([ESC, ESC_END]), bytes([END])).replace(
                    bytes([ESC, ESC_ESC]), bytes([ESC]))
                if frame:
                    yield frame
        else:
            while len(buf) >= 4:
                n = struct.unpack(">I", buf[:4])[0]
                if len(buf) < 4 + n:
                    break
                frame, buf = buf[4:4 + n], buf[4 + n:]
                yield frame


def selection(words):
    """The channels (or fixtures) of a selection such as 1 Thru 4 + 7."""
    out, i = [], 0
    while i < len(words):
        if words[i] == "+":
            i += 1
            continue
        start = int(words[i])
        if i + 2 < len(words) and words[i + 1] == "Thru":
            out.extend(range(start, int(words[i + 2]) + 1))
            i += 3
        else:
            out.append(start)
            i += 1
    return out


def focus_palettes(specs):
    """Focus palettes from --fp NUMBER=LABEL=CHANNELS arguments (channels as Eos sends
    them: 7-8,11), as (number, label, [channel strings]) in the given order."""
    out = []
    for spec in specs:
        number, label, chans = spec.split("=", 2)
        out.append((number, label, [c for c in chans.split(",") if c]))
    return out


def palette_replies(index, palette):
    """What Eos answers /eos/get/fp/index/<i> (or /eos/get/fp/<n>) with, as the Eos manual
    ("Integrating Your App with Eos") gives it: three OSC lists, the palette's (index, UID,
    label, absolute, locked), its channels' (index, UID, channel ranges) and its by-type
    channels' (index, UID, none here)."""
    number, label, chans = palette
    uid = "%08X-0000-0000-0000-00000000F%03d" % (index + 1, index)
    base = "/eos/out/get/fp/%s" % number
    return [
        ("%s/list/0/5" % base, [index, uid, label, 0, 0]),
        ("%s/channels/list/0/%d" % (base, 2 + len(chans)), [index, uid] + chans),
        ("%s/byType/list/0/2" % base, [index, uid]),
    ]
