#!/usr/bin/env python3
"""Counts the epochs with a 3D fix in receiver logs, independently of
navsync's decoders (the reference column of the census table).

A UBX frame is B5 62, class, id, little-endian length, payload, Fletcher-8
checksum (u-blox M8 protocol specification, UBX-13003221, "UBX frame
structure"); an NMEA sentence is $...*HH with an XOR checksum (NMEA 0183
§5.2.1). Scanning resumes one byte on after anything that is not an intact
frame. Counted, each epoch (iTOW) once:
  - NAV-PVT: fixType 3 or 4 and gnssFixOK (flags bit 0);
  - epochs without NAV-PVT: NAV-SOL (gpsFix at 10, flags at 11) or else
    NAV-STATUS (gpsFix at 4, flags at 5) with gpsFix 3 or 4 and GPSfixOK;
  - NMEA: GGA with fix quality 1..5 and an altitude.

Usage: scripts/ubx_fix_census.py LOG...
"""
import struct
import sys


def frames(b):
    i = 0
    while i < len(b):
        if b[i] == 0xB5 and b[i + 1:i + 2] == b"\x62" and i + 6 <= len(b):
            n = struct.unpack_from("<H", b, i + 4)[0]
            end = i + 8 + n
            if end <= len(b):
                ca = cb = 0
                for x in b[i + 2:end - 2]:
                    ca = (ca + x) & 0xFF
                    cb = (cb + ca) & 0xFF
                if bytes([ca, cb]) == b[end - 2:end]:
                    yield ("ubx", (b[i + 2], b[i + 3]), b[i + 6:end - 2])
                    i = end
                    continue
        if b[i] == 0x24:
            star = b.find(b"*", i, i + 256)
            if star > 0 and star + 3 <= len(b):
                body = b[i + 1:star]
                c = 0
                for x in body:
                    c ^= x
                try:
                    ok = int(b[star + 1:star + 3], 16) == c
                except ValueError:
                    ok = False
                if ok:
                    yield ("nmea", None, body.decode("ascii", "replace"))
                    i = star + 3
                    continue
        i += 1


def census(path):
    b = open(path, "rb").read()
    # gpsd test logs start with '#' comment lines.
    h = 0
    while b[h:h + 1] == b"#":
        h = b.index(b"\n", h) + 1
    pvt, sol, status = {}, {}, {}
    gga = 0
    for kind, mid, p in frames(b[h:]):
        if kind == "ubx":
            if mid == (0x01, 0x07) and len(p) == 92:
                pvt[struct.unpack_from("<I", p, 0)[0]] = p[20] in (3, 4) and p[21] & 1
            elif mid == (0x01, 0x06) and len(p) == 52:
                sol[struct.unpack_from("<I", p, 0)[0]] = p[10] in (3, 4) and p[11] & 1
            elif mid == (0x01, 0x03) and len(p) == 16:
                status[struct.unpack_from("<I", p, 0)[0]] = p[4] in (3, 4) and p[5] & 1
        else:
            f = p.split(",")
            if f[0][2:] == "GGA" and len(f) > 9 and f[6] in "12345" and f[6] and f[9]:
                gga += 1
    old = {**status, **sol}
    old_3d = sum(1 for t, ok in old.items() if ok and t not in pvt)
    return sum(1 for ok in pvt.values() if ok), old_3d, gga


if __name__ == "__main__":
    print("log\tNAV-PVT 3D\tNAV-SOL/STATUS 3D (no NAV-PVT)\tGGA with fix")
    for path in sys.argv[1:]:
        a, c, g = census(path)
        print(f"{path.rsplit('/', 1)[-1]}\t{a}\t{c}\t{g}")
