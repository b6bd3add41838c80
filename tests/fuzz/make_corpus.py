# Regenerates tests/fuzz/corpus/ from the golden files: the seeds themselves and a few
# truncated and mutated variants (CRCs fixed where the point is a deeper check).
# Usage: python3 tests/fuzz/make_corpus.py
import struct, zlib, os
HERE=os.path.dirname(os.path.abspath(__file__))
G=os.path.join(HERE,'..','codec','golden','')
C=os.path.join(HERE,'corpus','')
rd=lambda n: open(G+n,'rb').read()
model=rd('tiny_model_1.0.lex3dm'); ref=rd('tiny_model_ref_1.0.lex3dm'); alph=rd('tiny_alphabet_1.0.lex3da')
def parse(b):
    head=bytearray(b[:20]); ch=[]; pos=20
    while pos<len(b):
        n=struct.unpack_from('<Q',b,pos+4)[0]; ch.append([b[pos:pos+4], bytearray(b[pos+12:pos+12+n])]); pos+=16+n
    return head,ch
def build(head,ch):
    h=bytearray(head[:16]); h+=struct.pack('<I',zlib.crc32(bytes(h)))
    for t,p in ch:
        c=t+struct.pack('<Q',len(p))+bytes(p); h+=c+struct.pack('<I',zlib.crc32(c))
    return bytes(h)
def find(ch,t): return [c for c in ch if c[0]==t][0]
def write(n,b): open(C+n,'wb').write(b)
write('seed_model.lex3dm',model); write('seed_model_ref.lex3dm',ref); write('seed_alphabet.lex3da',alph)
write('empty',b'')
write('trunc_model_19',model[:19]); write('trunc_model_150',model[:150]); write('trunc_alphabet_60',alph[:60])
h,ch=parse(model); h[10]=1; write('model_minor_1.lex3dm',build(h,ch))
h,ch=parse(model); ch.insert(2,[b'note',bytearray(b'hello')]); write('model_optional_chunk.lex3dm',build(h,ch))
b=bytearray(model); b[-30]^=0x55; write('model_bad_crc.lex3dm',bytes(b))
h,ch=parse(model); p=find(ch,b'INST')[1]; struct.pack_into('<Q',p,0,1<<40); write('model_huge_count.lex3dm',build(h,ch))
h,ch=parse(model); p=find(ch,b'INST')[1]; n,rs=struct.unpack_from('<QQ',p,0); raw=bytearray(zlib.decompress(bytes(p[16:]))); raw[0]=7
find(ch,b'INST')[1]=bytearray(struct.pack('<QQ',n,rs)+zlib.compress(bytes(raw),9)); write('model_word_id_7.lex3dm',build(h,ch))
h,ch=parse(alph); p=find(ch,b'WORD')[1]; n,rs=struct.unpack_from('<QQ',p,0); raw=bytearray(zlib.decompress(bytes(p[16:]))); raw[-1]=0x80
find(ch,b'WORD')[1]=bytearray(struct.pack('<QQ',n,rs)+zlib.compress(bytes(raw),9)); write('alphabet_descriptor_m128.lex3da',build(h,ch))
h,ch=parse(alph); h[12]=4; write('alphabet_reserved_flag.lex3da',build(h,ch))
h,ch=parse(ref); h[8]=2; write('model_ref_major_2.lex3dm',build(h,ch))
# Format 1.5: the tiny model with a GEOR chunk (model.md §2.8) built here from the
# specification, as a golden file, and a few variants of it.
def geor(origin=(393925.823061,3689171.943122,3158.8627), unit=1.0, vunit=1.0, epsg=32642,
         scale=(0.001,0.001,1e-5), offset=(393775.823061,3689071.943122,3107.8627), minor=2, fmt=1, ge=0,
         strings=(b'WGS 84 / UTM zone 42N',b'metre',b'ALIRT',b'AA2010-CPED'),
         records=((b'LASF_Projection',2112,0,b'OGC Transformation Record',b'PROJCS["WGS 84 / UTM zone 42N"]\0'),)):
    p=struct.pack('<5dI6dBBH',*origin,unit,vunit,epsg,*scale,*offset,minor,fmt,ge)
    for s in strings: p+=struct.pack('<H',len(s))+s
    p+=struct.pack('<I',len(records))
    for u,i,e,d,data in records:
        p+=u.ljust(16,b'\0')+struct.pack('<HB',i,e)+d.ljust(32,b'\0')+struct.pack('<I',len(data))+data
    return bytearray(p)
h,ch=parse(model); h[10]=5; ch.insert(len(ch)-1,[b'GEOR',geor()]); g15=build(h,ch)
open(G+'tiny_model_georef_1.5.lex3dm','wb').write(g15); write('seed_model_georef_1.5.lex3dm',g15)
h,ch=parse(g15); h[10]=4; write('model_georef_minor_4.lex3dm',build(h,ch))
h,ch=parse(g15); find(ch,b'GEOR')[1]=geor(unit=0.0); write('model_georef_unit_0.lex3dm',build(h,ch))
h,ch=parse(g15); p=find(ch,b'GEOR')[1]; struct.pack_into('<I',p,len(p)-len(b'PROJCS["WGS 84 / UTM zone 42N"]\0')-4,1<<30); write('model_georef_record_len.lex3dm',build(h,ch))
write('trunc_model_georef_200',g15[:200])
