# patch_place_db.py IN OUT MODE: rewrites the first SCAN chunk of a place database
# (formats/place_db.md; a 2.0 file is first laid out as 1.0, which readers still accept),
# chunk CRC recomputed, for the command-line tests.
#  az_tiny: azimuth resolution 1e-6 rad, far finer than the image width allows
#  nofeat : no features (feature_count 0; the features and descriptor codes removed)
import struct, sys, zlib
src, dst, mode = sys.argv[1:4]
d = bytearray(open(src, 'rb').read())
assert d[:8] == b'LEX3DPDB'
(major,) = struct.unpack_from('<H', d, 8)
if major == 2:
    # A freshly built 2.0 file (PHDR, ALPH, SCAN..., PIDX after the two commit records) is
    # rewritten as the 1.0 layout the loader still reads: PHDR with the scan count, ALPH,
    # the SCAN chunks byte for byte, PEND.
    def chunk(typ, pl):
        hdr = typ + struct.pack('<Q', len(pl))
        return hdr + pl + struct.pack('<I', zlib.crc32(hdr + pl) & 0xffffffff)
    pos, phdr, body, scans = 76, None, bytearray(), 0
    while pos < len(d):
        typ = bytes(d[pos:pos+4]); (ln,) = struct.unpack_from('<Q', d, pos+4)
        pl = bytearray(d[pos+12:pos+12+ln]); pos += 12 + ln + 4
        if typ == b'PIDX':
            break
        if typ == b'PHDR':
            phdr = pl
        else:
            body += chunk(typ, pl)
            scans += typ == b'SCAN'
    struct.pack_into('<I', phdr, 0, scans)
    head = bytearray(d[:16]); struct.pack_into('<HH', head, 8, 1, 0)
    head += struct.pack('<I', zlib.crc32(head) & 0xffffffff)
    d = head + chunk(b'PHDR', phdr) + body + chunk(b'PEND', bytearray())
pos = 20; out = bytearray(d[:20]); dim = bits = None; done = False
while pos < len(d):
    typ = bytes(d[pos:pos+4]); (ln,) = struct.unpack_from('<Q', d, pos+4)
    pl = bytearray(d[pos+12:pos+12+ln]); pos += 12 + ln + 4
    if typ == b'PHDR':
        dim, = struct.unpack_from('<H', pl, 4); bits = pl[6]
    if typ == b'SCAN' and not done:
        done = True
        o = 0; (nl,) = struct.unpack_from('<H', pl, o); o += 2 + nl + 1 + 192
        (nw,) = struct.unpack_from('<I', pl, o); o += 4 + 8 * nw
        (nf,) = struct.unpack_from('<I', pl, o); fo = o; o += 4
        codes = nf * dim; cb = codes if bits == 8 else (codes + 1) // 2
        if mode == 'nofeat':
            pl = pl[:fo] + struct.pack('<I', 0) + pl[o + 20 * nf + cb:]
        else:
            o += 20 * nf + cb
            w, h, full = struct.unpack_from('<HHB', pl, o); o += 5
            struct.pack_into('<d', pl, o, 1e-6)
    hdr = typ + struct.pack('<Q', len(pl))
    out += hdr + pl + struct.pack('<I', zlib.crc32(hdr + pl) & 0xffffffff)
open(dst, 'wb').write(out)
