// The sequence file (formats/sequence.md): round trip, and every reader check.

#include <gtest/gtest.h>

#include <cstdint>
#include <string>
#include <vector>

#include "lex3d/codec/codec.hpp"

namespace lex3d::codec {
namespace {

using Bytes = std::vector<std::uint8_t>;

Alphabet tiny_alphabet() {
  Alphabet a;
  a.word_radius = 0.25;
  a.point_spacing = 0.025;
  a.descriptor_dim = 2;
  a.words.resize(2);
  a.words[0].points = {{0.0F, 0.0F, 0.0F}, {0.1F, 0.0F, 0.0F}};
  a.words[0].descriptor = {0.5F, -0.5F};
  a.words[1].points = {{0.0F, 0.1F, 0.0F}};
  a.words[1].descriptor = {-0.25F, 1.0F};
  return a;
}

struct Fixture {
  Bytes alphabet_file = encode_alphabet(tiny_alphabet());
  SequenceData data;
  Fixture() {
    data.alphabet_file = alphabet_file;
    for (int s = 0; s < 3; ++s) {
      ModelData d;
      d.input_points = 100U + static_cast<std::uint64_t>(s);
      d.alphabet_hash = alphabet_hash(alphabet_file);
      for (int i = 0; i <= s; ++i) {
        Pose T = Pose::Identity();
        T.translation() = Eigen::Vector3d(i, -s, 0.5);
        d.model.instances.push_back({static_cast<std::uint32_t>(i % 2), T, 0});
      }
      data.model_files.push_back(encode_model(d));
    }
  }
};

/// The file with chunk `index` (0 = QHDR) replaced by `type`/`payload`, CRCs recomputed by
/// re-framing through a minimal writer of the container rules.
Bytes frame(const std::vector<std::pair<std::string, Bytes>>& chunks, std::uint32_t flags = 0, std::uint8_t minor = 0) {
  Fixture f;
  Bytes good = encode_sequence(f.data);
  Bytes out(good.begin(), good.begin() + 20);  // header of a valid file
  if (flags != 0 || minor != 0) {
    out[10] = minor;
    out[12] = static_cast<std::uint8_t>(flags);
    const auto crc = [](const std::uint8_t* p, std::size_t n) {
      std::uint32_t c = 0xFFFFFFFFU;
      for (std::size_t i = 0; i < n; ++i) {
        c ^= p[i];
        for (int k = 0; k < 8; ++k) c = (c >> 1) ^ (0xEDB88320U & (0U - (c & 1U)));
      }
      return ~c;
    };
    const std::uint32_t h = crc(out.data(), 16);
    for (int i = 0; i < 4; ++i) out[16 + i] = static_cast<std::uint8_t>(h >> (8 * i));
  }
  for (const auto& [type, payload] : chunks) {
    Bytes c(type.begin(), type.end());
    for (int i = 0; i < 8; ++i) c.push_back(static_cast<std::uint8_t>(static_cast<std::uint64_t>(payload.size()) >> (8 * i)));
    c.insert(c.end(), payload.begin(), payload.end());
    std::uint32_t v = 0xFFFFFFFFU;
    for (const std::uint8_t b : c) {
      v ^= b;
      for (int k = 0; k < 8; ++k) v = (v >> 1) ^ (0xEDB88320U & (0U - (v & 1U)));
    }
    v = ~v;
    out.insert(out.end(), c.begin(), c.end());
    for (int i = 0; i < 4; ++i) out.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  }
  return out;
}

Bytes u64(std::uint64_t v) {
  Bytes b;
  for (int i = 0; i < 8; ++i) b.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  return b;
}

TEST(Sequence, RoundTripAndModelsDecode) {
  Fixture f;
  const Bytes file = encode_sequence(f.data);
  EXPECT_TRUE(is_sequence_file(file));
  EXPECT_FALSE(is_sequence_file(f.data.model_files[0]));
  const auto r = decode_sequence(file);
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  EXPECT_EQ(r.value().alphabet_file, f.alphabet_file);
  ASSERT_EQ(r.value().model_files, f.data.model_files);
  for (std::size_t s = 0; s < 3; ++s) {
    const auto m = decode_model(r.value().model_files[s], &r.value().alphabet_file);
    ASSERT_TRUE(m.ok()) << m.status().to_string();
    EXPECT_EQ(m.value().model.instances.size(), s + 1);
  }
  EXPECT_EQ(encode_sequence(f.data), file) << "deterministic";
  const auto info = inspect(file);
  ASSERT_TRUE(info.ok());
  EXPECT_EQ(info.value().kind, "sequence");
  EXPECT_EQ(info.value().chunks.size(), 6U);
  // An empty sequence is a valid one.
  SequenceData empty;
  empty.alphabet_file = f.alphabet_file;
  const auto e = decode_sequence(encode_sequence(empty));
  ASSERT_TRUE(e.ok()) << e.status().to_string();
  EXPECT_TRUE(e.value().model_files.empty());
}

TEST(Sequence, EncoderRejectsModelsThatDoNotReferenceTheAlphabet) {
  Fixture f;
  ModelData embedded;
  embedded.alphabet = tiny_alphabet();
  f.data.model_files.push_back(encode_model(embedded));
  EXPECT_THROW((void)encode_sequence(f.data), std::invalid_argument);
  Fixture g;
  g.data.alphabet_file = encode_alphabet(Alphabet{});  // another alphabet: hashes differ
  EXPECT_THROW((void)encode_sequence(g.data), std::invalid_argument);
  Fixture h;
  h.data.alphabet_file = Bytes{1, 2, 3};
  EXPECT_THROW((void)encode_sequence(h.data), std::invalid_argument);
}

TEST(Sequence, TruncationAtEveryByteIsRejected) {
  Fixture f;
  const Bytes file = encode_sequence(f.data);
  for (std::size_t n = 0; n < file.size(); ++n) {
    const auto r = decode_sequence(Bytes(file.begin(), file.begin() + static_cast<std::ptrdiff_t>(n)));
    ASSERT_FALSE(r.ok()) << n;
    EXPECT_EQ(r.status().code(), ErrorCode::kBadData);
    ASSERT_TRUE(r.status().offset().has_value());
    EXPECT_LE(*r.status().offset(), n);
  }
}

TEST(Sequence, ReaderChecks) {
  Fixture f;
  const Bytes a = f.alphabet_file;
  const Bytes& m0 = f.data.model_files[0];
  auto bad = [](const Bytes& file, const std::string& needle) {
    const auto r = decode_sequence(file);
    ASSERT_FALSE(r.ok()) << needle;
    EXPECT_NE(r.status().message().find(needle), std::string::npos) << r.status().to_string();
  };
  EXPECT_TRUE(decode_sequence(frame({{"QHDR", u64(1)}, {"ALPH", a}, {"SCAN", m0}, {"QEND", {}}})).ok());
  EXPECT_TRUE(decode_sequence(frame({{"QHDR", u64(1)}, {"note", {7}}, {"ALPH", a}, {"SCAN", m0}, {"QEND", {}}})).ok())
      << "optional chunks are skipped";
  bad(frame({{"ALPH", a}, {"QHDR", u64(0)}, {"QEND", {}}}), "first chunk");
  bad(frame({{"QHDR", Bytes(7, 0)}, {"ALPH", a}, {"QEND", {}}}), "expected 8");
  bad(frame({{"QHDR", u64(1000)}, {"ALPH", a}, {"QEND", {}}}), "cannot fit");
  bad(frame({{"QHDR", u64(1)}, {"SCAN", m0}, {"ALPH", a}, {"QEND", {}}}), "before the required chunk 'ALPH'");
  bad(frame({{"QHDR", u64(0)}, {"ALPH", Bytes{1, 2}}, {"QEND", {}}}), "alphabet");
  bad(frame({{"QHDR", u64(2)}, {"ALPH", a}, {"SCAN", m0}, {"QEND", {}}}), "QHDR scan_count says 2");
  bad(frame({{"QHDR", u64(0)}, {"ALPH", a}, {"SCAN", m0}, {"QEND", {}}}), "more 'SCAN' chunks");
  bad(frame({{"QHDR", u64(0)}, {"ALPH", a}, {"ALPH", a}, {"QEND", {}}}), "repeated or out of order");
  bad(frame({{"QHDR", u64(0)}, {"ALPH", a}, {"QHDR", u64(0)}, {"QEND", {}}}), "repeated or out of order");
  bad(frame({{"QHDR", u64(0)}, {"ALPH", a}, {"XTRA", {1}}, {"QEND", {}}}), "unknown required chunk");
  bad(frame({{"QHDR", u64(0)}, {"ALPH", a}, {"QEND", {1}}}), "must be empty");
  bad(frame({{"QHDR", u64(0)}, {"ALPH", a}, {"QEND", {}}}, 4), "reserved flag");
  Bytes trailing = frame({{"QHDR", u64(0)}, {"ALPH", a}, {"QEND", {}}});
  trailing.push_back(0);
  bad(trailing, "after the end chunk");
  Bytes crc = encode_sequence(f.data);
  crc[40] ^= 1;
  bad(crc, "CRC mismatch");
  // A scan referencing another alphabet decodes its framing but not the model.
  ModelData other;
  other.alphabet_hash = 42;
  const auto r = decode_sequence(frame({{"QHDR", u64(1)}, {"ALPH", a}, {"SCAN", encode_model(other)}, {"QEND", {}}}));
  ASSERT_TRUE(r.ok());
  EXPECT_FALSE(decode_model(r.value().model_files[0], &r.value().alphabet_file).ok());
}

/// A `snam` payload: u16 length and bytes, a name each.
Bytes snam(const std::vector<std::string>& names) {
  Bytes b;
  for (const auto& n : names) {
    b.push_back(static_cast<std::uint8_t>(n.size()));
    b.push_back(static_cast<std::uint8_t>(n.size() >> 8));
    b.insert(b.end(), n.begin(), n.end());
  }
  return b;
}

TEST(Sequence, ScanNamesRoundTripIn1_1) {
  Fixture f;
  const Bytes v10 = encode_sequence(f.data);
  EXPECT_EQ(v10[10], 0) << "without names a file stays 1.0";
  f.data.names = {"000000", "scan b", "c.part"};
  const Bytes v11 = encode_sequence(f.data);
  EXPECT_EQ(v11[10], 1);
  // The exact bytes (sequence.md §2): 'snam' right after 'ALPH'.
  const auto& m = f.data.model_files;
  EXPECT_EQ(v11, frame({{"QHDR", u64(3)}, {"ALPH", f.alphabet_file}, {"snam", snam(f.data.names)},
                        {"SCAN", m[0]}, {"SCAN", m[1]}, {"SCAN", m[2]}, {"QEND", {}}}, 0, 1));
  const auto r = decode_sequence(v11);
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  EXPECT_EQ(r.value().names, f.data.names);
  EXPECT_EQ(r.value().model_files, f.data.model_files);
  // A 1.0 file decodes without names; 'snam' may stand anywhere after QHDR.
  EXPECT_TRUE(decode_sequence(v10).value().names.empty());
  const auto late = decode_sequence(frame({{"QHDR", u64(1)}, {"ALPH", f.alphabet_file}, {"SCAN", m[0]},
                                           {"snam", snam({"x"})}, {"QEND", {}}}));
  ASSERT_TRUE(late.ok()) << late.status().to_string();
  EXPECT_EQ(late.value().names, std::vector<std::string>{"x"});
  // The names are what a reader of 1.0 skips: the same file without 'snam' holds the same scans.
  EXPECT_EQ(decode_sequence(frame({{"QHDR", u64(3)}, {"ALPH", f.alphabet_file}, {"SCAN", m[0]}, {"SCAN", m[1]},
                                   {"SCAN", m[2]}, {"QEND", {}}}, 0, 1)).value().model_files, m);
}

TEST(Sequence, ScanNameChecks) {
  Fixture f;
  const Bytes a = f.alphabet_file;
  const Bytes& m0 = f.data.model_files[0];
  auto bad = [&](const Bytes& names, const std::string& needle) {
    const auto r = decode_sequence(frame({{"QHDR", u64(1)}, {"ALPH", a}, {"snam", names}, {"SCAN", m0}, {"QEND", {}}}));
    ASSERT_FALSE(r.ok()) << needle;
    EXPECT_EQ(r.status().code(), ErrorCode::kBadData);
    EXPECT_NE(r.status().message().find(needle), std::string::npos) << r.status().to_string();
  };
  bad(snam({"a", "b"}), "bytes after its names");
  bad(Bytes{5, 0, 'a'}, "does not fit the chunk");
  bad(Bytes{1}, "ends inside name 0");
  bad(snam({""}), "name 0 is empty");
  bad(snam({"a/b"}), "holds '/'");
  bad(snam({".."}), "name 0");
  bad(snam({std::string(256, 'n')}), "too long");
  bad(snam({std::string("a\0b", 3)}), "NUL");
  const auto twice = decode_sequence(frame({{"QHDR", u64(1)}, {"ALPH", a}, {"snam", snam({"a"})}, {"snam", snam({"a"})},
                                            {"SCAN", m0}, {"QEND", {}}}));
  ASSERT_FALSE(twice.ok());
  EXPECT_NE(twice.status().message().find("repeated"), std::string::npos);
  const auto two = decode_sequence(frame({{"QHDR", u64(2)}, {"ALPH", a}, {"snam", snam({"a", "a"})}, {"SCAN", m0},
                                          {"SCAN", m0}, {"QEND", {}}}));
  ASSERT_FALSE(two.ok());
  EXPECT_NE(two.status().message().find("name 1"), std::string::npos) << two.status().to_string();
  // The encoder refuses what the reader would.
  f.data.names = {"a", "b"};
  EXPECT_THROW((void)encode_sequence(f.data), std::invalid_argument);  // 2 names, 3 scans
  f.data.names = {"a", "b", "a"};
  EXPECT_THROW((void)encode_sequence(f.data), std::invalid_argument);
  f.data.names = {"a", "b", "c/d"};
  EXPECT_THROW((void)encode_sequence(f.data), std::invalid_argument);
}

}  // namespace
}  // namespace lex3d::codec
