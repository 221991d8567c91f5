#!/usr/bin/env python3
"""An independent reader of USITT ASCII show files ("ASCII Text Representation for Lighting
Console Data", version 3.0, Ident 3:0, 1992), written from the standard, for the export
tests. Prints the cues it read as JSON:

  [{"cue": "1", "text": "...", "up": 3.0, "down": 3.0, "levels": {"12": 62.0, ...}}, ...]

The rules it applies, as the standard states them: one instruction per line, at most 80
characters; keywords are case-insensitive; the delimiters space, comma, <, >, =, @ and /
are interchangeable; "!" starts a comment to the end of the line; a CUE starts a cue,
TEXT, UP, DOWN and CHAN lines belong to the cue before them (CHAN lines accumulate:
channel/level pairs, levels in percent, FL for full, Hxx for hexadecimal 0..FF);
keywords starting with "$" are manufacturer extensions, skipped; ENDDATA ends the data.
A violation (a long line, a CHAN outside a cue, a level it cannot read) exits non-zero
with the line number.

Usage: usitt_ascii.py FILE
"""

import json
import re
import sys

DELIMS = re.compile(r"[ \t,<>=@/]+")


def level(word, where):
    w = word.upper()
    if w == "FL":
        return 100.0
    if w.startswith("H"):
        return round(int(w[1:], 16) * 100.0 / 255.0, 1)
    v = float(w)
    if not 0.0 <= v <= 100.0:
        sys.exit("%s: level %s is not 0..100" % (where, word))
    return v


def seconds(word):
    if ":" in word:
        m, s = word.split(":")
        return int(m) * 60 + float(s)
    return float(word)


def main():
    path = sys.argv[1]
    cues, cue, ended = [], None, False
    with open(path, encoding="ascii") as f:
        for n, raw in enumerate(f, 1):
            where = "%s:%d" % (path, n)
            line = raw.rstrip("\r\n")
            if len(line) > 80:
                sys.exit("%s: longer than 80 characters" % where)
            if ended:
                continue
            keyword_part = line.split("!", 1)[0]
            head = keyword_part.strip().split(None, 1)
            if not head:
                continue
            keyword = head[0].upper()
            rest = head[1] if len(head) > 1 else ""
            if keyword.startswith("$"):
                continue
            if keyword == "ENDDATA":
                ended = True
            elif keyword == "CUE":
                cue = {"cue": DELIMS.split(rest.strip())[0], "text": "", "up": None,
                       "down": None, "levels": {}}
                cues.append(cue)
            elif keyword in ("TEXT", "UP", "DOWN", "CHAN"):
                if cue is None:
                    sys.exit("%s: %s outside a cue" % (where, keyword))
                if keyword == "TEXT":
                    cue["text"] = rest.strip()
                elif keyword in ("UP", "DOWN"):
                    cue[keyword.lower()] = seconds(DELIMS.split(rest.strip())[0])
                else:
                    words = [w for w in DELIMS.split(rest.strip()) if w]
                    if len(words) % 2:
                        sys.exit("%s: channel without a level" % where)
                    for i in range(0, len(words), 2):
                        cue["levels"][str(int(words[i]))] = level(words[i + 1], where)
            # IDENT, MANUFACTURER, CONSOLE, CLEAR and the rest: not cue data.
    if not ended:
        sys.exit("%s: no ENDDATA" % path)
    json.dump(cues, sys.stdout)
    return 0


if __name__ == "__main__":
    sys.exit(main())
