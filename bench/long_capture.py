#!/usr/bin/env python3
"""Writes a long Velodyne capture from a short one, for measuring how lex3d reads captures
of any length: the packets of the capture's first whole turn, repeated TURNS times, each
repetition's record times and packet timestamps moved on by one turn's span (the azimuths
repeat, so the turns join as the sensor's would).

usage: long_capture.py IN.pcap OUT.pcap TURNS

Only classic libpcap files of Ethernet + IPv4 + UDP records carrying 1206-byte Velodyne
data packets (no IP fragments) are handled.
"""
import struct
import sys


def read_records(path):
    with open(path, "rb") as f:
        data = f.read()
    magic = struct.unpack("<I", data[:4])[0]
    if magic not in (0xA1B2C3D4, 0xA1B23C4D):
        sys.exit(f"{path}: not a little-endian libpcap file")
    nano = magic == 0xA1B23C4D
    header = data[:24]
    records = []
    at = 24
    while at + 16 <= len(data):
        sec, frac, incl, orig = struct.unpack("<IIII", data[at:at + 16])
        records.append([sec, frac, data[at + 16:at + 16 + incl], orig])
        at += 16 + incl
    return header, nano, records


def payload_offset(frame):
    if len(frame) < 14 + 20 or frame[12:14] != b"\x08\x00":
        return None
    ihl = (frame[14] & 15) * 4
    at = 14 + ihl + 8
    if frame[23] != 17 or len(frame) - at != 1206 or frame[at] != 0xFF or frame[at + 1] != 0xEE:
        return None
    return at


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    src, dst, turns = sys.argv[1], sys.argv[2], int(sys.argv[3])
    header, nano, records = read_records(src)
    packets = [(r, payload_offset(r[2])) for r in records]
    packets = [(r, at) for r, at in packets if at is not None]
    if len(packets) < 2:
        sys.exit(f"{src}: fewer than two Velodyne data packets")
    azimuth = [struct.unpack("<H", r[2][at + 2:at + 4])[0] / 100.0 for r, at in packets]
    # the first packet whose azimuth comes back round to the first one's: one whole turn before it
    turned, end = 0.0, None
    for i in range(1, len(azimuth)):
        step = (azimuth[i] - azimuth[i - 1]) % 360.0
        turned += step
        if turned >= 360.0:
            end = i
            break
    if end is None:
        sys.exit(f"{src}: less than one turn of packets")
    unit = 1_000_000_000 if nano else 1_000_000
    t0 = packets[0][0][0] * unit + packets[0][0][1]
    span_capture = packets[end][0][0] * unit + packets[end][0][1] - t0
    stamp = lambda r, at: struct.unpack("<I", r[2][at + 1200:at + 1204])[0]
    span_us = (stamp(*packets[end]) - stamp(*packets[0])) % 3_600_000_000
    with open(dst, "wb") as f:
        f.write(header)
        for k in range(turns):
            for r, at in packets[:end]:
                t = r[0] * unit + r[1] + k * span_capture
                frame = bytearray(r[2])
                frame[at + 1200:at + 1204] = struct.pack("<I", (stamp(r, at) + k * span_us) % 3_600_000_000)
                f.write(struct.pack("<IIII", t // unit, t % unit, len(frame), r[3]))
                f.write(frame)
    print(f"{dst}: {turns} turns of {end} packets ({turns * end} packets)")


if __name__ == "__main__":
    main()
