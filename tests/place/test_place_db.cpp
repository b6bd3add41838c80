// The place database file (formats/place_db.md 2.0): opening reads only the index and
// gives the same answers as the scans held in memory; appends commit atomically (a crash
// before the commit record leaves the old database); every index field is checked; 1.0
// files are read and upgraded.

#include <zlib.h>

#include <cmath>
#include <cstring>
#include <functional>
#include <random>
#include <string>

#include <gtest/gtest.h>

#include "lex3d/codec/codec.hpp"
#include "lex3d/io/io.hpp"
#include "lex3d/io/mapped_file.hpp"
#include "lex3d/place/place.hpp"
#include "place/internal.hpp"
#include "support/test_support.hpp"

namespace lex3d {
namespace {

using Bytes = std::vector<std::uint8_t>;

std::uint32_t crc_of(const std::uint8_t* p, std::size_t n) {
  return static_cast<std::uint32_t>(crc32(crc32(0L, Z_NULL, 0), p, static_cast<uInt>(n)));
}
std::uint64_t get64(const Bytes& b, std::size_t at) {
  std::uint64_t v = 0;
  for (int k = 0; k < 8; ++k) v |= static_cast<std::uint64_t>(b[at + static_cast<std::size_t>(k)]) << (8 * k);
  return v;
}
void put64(Bytes& b, std::size_t at, std::uint64_t v) {
  for (int k = 0; k < 8; ++k) b[at + static_cast<std::size_t>(k)] = static_cast<std::uint8_t>(v >> (8 * k));
}
void put32(Bytes& b, std::size_t at, std::uint32_t v) {
  for (int k = 0; k < 4; ++k) b[at + static_cast<std::size_t>(k)] = static_cast<std::uint8_t>(v >> (8 * k));
}

Alphabet tiny_alphabet(std::size_t words) {
  Alphabet a;
  a.descriptor_dim = 4;
  a.word_radius = 0.4;
  a.words.resize(words);
  for (auto& w : a.words) w.descriptor = {0.1F, 0.2F, 0.3F, 0.4F};
  return a;
}

// A synthetic scan: random words from `alphabet_words`, a few features, a small coarse image.
PlaceScan synthetic_scan(std::uint32_t seed, std::size_t alphabet_words) {
  std::mt19937 rng(seed);
  PlaceScan s;
  s.name = "s" + std::to_string(seed);
  std::uniform_int_distribution<std::uint32_t> count(1, 9);
  for (std::uint32_t w = 0; w < alphabet_words; ++w)
    if (rng() % 3 == 0) s.words.emplace_back(w, count(rng));
  s.descriptor_dim = 4;
  s.descriptor_bits = PlaceStorageParams{}.descriptor_bits;
  std::uniform_real_distribution<float> u(-10.0F, 10.0F);
  for (int i = 0; i < 12; ++i) {
    PlaceFeature f;
    f.position = Eigen::Vector3f(u(rng), u(rng), 0.1F * u(rng));
    s.features.push_back(f);
    for (int k = 0; k < 4; ++k) s.descriptor_codes.push_back(static_cast<std::uint8_t>(rng() % 16));
  }
  s.coarse.width = 8;
  s.coarse.height = 3;
  s.coarse.full_circle = true;
  s.coarse.azimuth_resolution_rad = 2 * M_PI / 8;
  s.coarse.azimuth_max_rad = M_PI;
  s.coarse.elevation_resolution_rad = 0.1;
  s.coarse.row_edges = {0.15, 0.05, -0.05, -0.15};
  s.coarse.state.assign(24, PixelState::kValid);
  s.coarse.range.assign(24, 0.0F);
  for (std::size_t i = 0; i < 24; ++i) s.coarse.range[i] = detail::dequantise_range(detail::quantise_range(3.0F + 0.1F * static_cast<float>(i % 7), 0.02), 0.02);
  s.coarse.state[5] = PixelState::kMaxRange;
  s.coarse.state[6] = PixelState::kUnobserved;
  detail::finish_place_scan(s);
  return s;
}

void put_piece(Bytes& file, const PlaceFileWriter::Piece& p) {
  if (file.size() < p.offset + p.bytes.size()) file.resize(static_cast<std::size_t>(p.offset + p.bytes.size()));
  std::memcpy(file.data() + p.offset, p.bytes.data(), p.bytes.size());
}

void expect_same_retrieval(const PlaceDatabase& a, const PlaceDatabase& b, const std::vector<PlaceScan>& queries) {
  ASSERT_EQ(a.size(), b.size());
  for (const auto& q : queries) {
    const auto ra = a.retrieve(q, 1000), rb = b.retrieve(q, 1000);
    ASSERT_EQ(ra.size(), rb.size()) << q.name;
    for (std::size_t i = 0; i < ra.size(); ++i) {
      EXPECT_EQ(ra[i].first, rb[i].first) << q.name << " rank " << i;
      EXPECT_EQ(ra[i].second, rb[i].second) << q.name << " rank " << i;  // bit for bit
    }
  }
}

void expect_same_scan(const PlaceScan& x, const PlaceScan& y) {
  EXPECT_EQ(x.name, y.name);
  EXPECT_EQ(x.words, y.words);
  EXPECT_EQ(x.descriptor_codes, y.descriptor_codes);
  EXPECT_EQ(x.validation, y.validation);
  ASSERT_EQ(x.features.size(), y.features.size());
  for (std::size_t k = 0; k < x.features.size(); ++k) EXPECT_EQ(x.features[k].position, y.features[k].position);
  EXPECT_EQ(x.coarse.state, y.coarse.state);
  EXPECT_EQ(x.dense_points.size(), y.dense_points.size());
}

constexpr std::size_t kWords = 40;

// A 2.0 file of scans 0..n-1 written piece by piece, and the same scans in memory.
Bytes write_file(std::uint32_t n, const Alphabet& a) {
  PlaceFileWriter w(PlaceStorageParams{}, &a, a.descriptor_dim);
  Bytes file;
  put_piece(file, w.begin());
  for (std::uint32_t i = 0; i < n; ++i) put_piece(file, w.add(synthetic_scan(i, kWords)));
  const auto [idx, commit] = w.finish();
  put_piece(file, idx);
  put_piece(file, commit);
  return file;
}

PlaceDatabase in_memory(std::uint32_t from, std::uint32_t to, const Alphabet& a) {
  PlaceDatabase db;
  db.set_alphabet(a);
  for (std::uint32_t i = from; i < to; ++i) db.add(synthetic_scan(i, kWords));
  return db;
}

std::vector<PlaceScan> queries() {
  std::vector<PlaceScan> q;
  for (std::uint32_t i = 100; i < 110; ++i) q.push_back(synthetic_scan(i, kWords));
  return q;
}

TEST(PlaceFile, OpenedFileRetrievesAsTheScansInMemory) {
  const Alphabet a = tiny_alphabet(kWords);
  const Bytes file = write_file(30, a);
  auto db = PlaceDatabase::load(file);
  ASSERT_TRUE(db.ok()) << db.status().to_string();
  EXPECT_EQ(db.value().file_info().major, 2);
  EXPECT_EQ(db.value().stored_count(), 30U);
  const PlaceDatabase mem = in_memory(0, 30, a);
  expect_same_retrieval(mem, db.value(), queries());
  for (std::size_t i = 0; i < 30; ++i) {
    EXPECT_EQ(db.value().name(i), mem.name(i));
    expect_same_scan(mem.scan(i), db.value().scan(i));
  }
  // save() of the in-memory database gives the same bytes as the piecewise writer.
  EXPECT_EQ(mem.save(), file);
  // Adding in memory after opening: retrieval over stored + added equals all in memory.
  PlaceDatabase mixed = db.value();
  for (std::uint32_t i = 30; i < 36; ++i) mixed.add(synthetic_scan(i, kWords));
  expect_same_retrieval(in_memory(0, 36, a), mixed, queries());
  // The opened database was not changed by the copy's adds.
  EXPECT_EQ(db.value().size(), 30U);
}

TEST(PlaceFile, AppendThenReload) {
  const Alphabet a = tiny_alphabet(kWords);
  Bytes file = write_file(20, a);
  auto db = PlaceDatabase::load(file);
  ASSERT_TRUE(db.ok());
  const std::uint64_t old_index = db.value().file_info().index_bytes;
  PlaceFileWriter w(db.value());
  EXPECT_EQ(w.start(), file.size());
  EXPECT_TRUE(w.begin().bytes.empty());
  for (std::uint32_t i = 20; i < 32; ++i) put_piece(file, w.add(synthetic_scan(i, kWords)));
  const auto [idx, commit] = w.finish();
  put_piece(file, idx);
  put_piece(file, commit);
  auto back = PlaceDatabase::load(file);
  ASSERT_TRUE(back.ok()) << back.status().to_string();
  EXPECT_EQ(back.value().size(), 32U);
  EXPECT_EQ(back.value().file_info().commit_sequence, 2U);
  EXPECT_EQ(back.value().file_info().dead_bytes, old_index);
  expect_same_retrieval(in_memory(0, 32, a), back.value(), queries());
  for (std::size_t i = 0; i < 32; ++i) EXPECT_EQ(back.value().name(i), "s" + std::to_string(i));
  expect_same_scan(back.value().scan(25), synthetic_scan(25, kWords));
  // A second append uses the other commit record.
  PlaceFileWriter w2(back.value());
  put_piece(file, w2.add(synthetic_scan(32, kWords)));
  const auto [idx2, commit2] = w2.finish();
  put_piece(file, idx2);
  put_piece(file, commit2);
  EXPECT_NE(commit.offset, commit2.offset);
  auto third = PlaceDatabase::load(file);
  ASSERT_TRUE(third.ok()) << third.status().to_string();
  expect_same_retrieval(in_memory(0, 33, a), third.value(), queries());
}

TEST(PlaceFile, CrashBeforeTheCommitKeepsTheOldDatabase) {
  const Alphabet a = tiny_alphabet(kWords);
  const Bytes before = write_file(10, a);
  auto db = PlaceDatabase::load(before);
  ASSERT_TRUE(db.ok());
  PlaceFileWriter w(db.value());
  Bytes after = before;
  for (std::uint32_t i = 10; i < 14; ++i) put_piece(after, w.add(synthetic_scan(i, kWords)));
  const auto [idx, commit] = w.finish();
  put_piece(after, idx);
  const PlaceDatabase old_mem = in_memory(0, 10, a);
  // Cut anywhere in what the append wrote, the commit record not yet written: the old database.
  for (std::size_t cut = before.size(); cut <= after.size(); cut += 97) {
    const Bytes crashed(after.begin(), after.begin() + static_cast<std::ptrdiff_t>(cut));
    auto r = PlaceDatabase::load(crashed);
    ASSERT_TRUE(r.ok()) << "cut at " << cut << ": " << r.status().to_string();
    EXPECT_EQ(r.value().size(), 10U);
    EXPECT_EQ(r.value().file_info().ignored_tail_bytes, cut - before.size());
    if (cut == before.size() + 97) expect_same_retrieval(old_mem, r.value(), queries());
  }
  // A torn commit record (half written) fails its CRC: the old record stays in force.
  Bytes torn = after;
  std::memcpy(torn.data() + commit.offset, commit.bytes.data(), 14);
  auto r = PlaceDatabase::load(torn);
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  EXPECT_EQ(r.value().size(), 10U);
  // The commit written, then the file cut short of its end: an error naming the byte.
  put_piece(after, commit);
  ASSERT_EQ(PlaceDatabase::load(after).value().size(), 14U);
  for (const std::size_t cut : {after.size() - 1, before.size() + 10, before.size()}) {
    const Bytes cut_file(after.begin(), after.begin() + static_cast<std::ptrdiff_t>(cut));
    auto c = PlaceDatabase::load(cut_file);
    ASSERT_FALSE(c.ok()) << cut;
    EXPECT_EQ(c.status().code(), ErrorCode::kBadData);
    EXPECT_NE(c.status().message().find("truncated"), std::string::npos) << c.status().message();
    EXPECT_EQ(c.status().offset().value_or(0), cut);
  }
}

// The PIDX chunk of a file: offset of its payload and its length.
std::pair<std::size_t, std::size_t> pidx_of(const Bytes& file) {
  const std::size_t rec = get64(file, 20) > get64(file, 48) ? 20 : 48;
  const auto at = static_cast<std::size_t>(get64(file, rec + 16));
  return {at + 12, static_cast<std::size_t>(get64(file, at + 4))};
}
void fix_pidx_crc(Bytes& file) {
  const auto [p, len] = pidx_of(file);
  put32(file, p + len, crc_of(file.data() + p - 12, 12 + len));
}
void fix_commit_crc(Bytes& file, std::size_t rec) { put32(file, rec + 24, crc_of(file.data() + rec, 24)); }

TEST(PlaceFile, EveryIndexFieldIsChecked) {
  const Alphabet a = tiny_alphabet(kWords);
  const Bytes good = write_file(3, a);
  ASSERT_TRUE(PlaceDatabase::load(good).ok());
  const auto [p, len] = pidx_of(good);
  const std::uint32_t n = 3;
  const std::size_t entries = p + 24;
  const std::size_t names = entries + 36 * n;
  const std::uint64_t names_len = get64(good, p + 16);
  const std::size_t word_start = names + static_cast<std::size_t>(names_len);
  const std::size_t postings = word_start + 8 * (kWords + 1);
  struct Case {
    const char* what;
    std::function<void(Bytes&)> edit;
    const char* message;
  };
  const std::vector<Case> cases = {
      {"scan count", [&](Bytes& b) { put32(b, p, 1u << 25); }, "scan count"},
      {"scan count + 1", [&](Bytes& b) { put32(b, p, n + 1); }, "add up"},
      {"word slots beyond the alphabet", [&](Bytes& b) { put32(b, p + 4, kWords + 1); }, "word count"},
      {"posting count", [&](Bytes& b) { put64(b, p + 8, get64(b, p + 8) + 1); }, "add up"},
      {"names length", [&](Bytes& b) { put64(b, p + 16, ~std::uint64_t{0}); }, "add up"},
      {"entry offset inside PHDR", [&](Bytes& b) { put64(b, entries, 30); }, "outside"},
      {"entry offset past the index", [&](Bytes& b) { put64(b, entries + 36, get64(b, 48 + 16) + 1000); }, "outside"},
      {"entries overlap", [&](Bytes& b) { put64(b, entries + 36, get64(b, entries)); }, "outside"},
      {"payload length", [&](Bytes& b) { put64(b, entries + 8, ~std::uint64_t{0} - 3); }, "outside"},
      {"word total", [&](Bytes& b) { put32(b, entries + 16, 1); }, "word total"},
      {"name offset", [&](Bytes& b) { put32(b, entries + 20, 1u << 30); }, "name"},
      {"reserved", [&](Bytes& b) { b[entries + 26] = 1; }, "name"},
      {"norm NaN", [&](Bytes& b) { put64(b, entries + 28, 0x7FF8000000000000ULL); }, "norm"},
      {"norm negative", [&](Bytes& b) { put64(b, entries + 28, 0xBFF0000000000000ULL); }, "norm"},
      {"first word start", [&](Bytes& b) { put64(b, word_start, 1); }, "word starts"},
      {"word starts decrease", [&](Bytes& b) { put64(b, word_start + 8, get64(b, word_start + 16) + 1); }, "word starts"},
      {"posting scan", [&](Bytes& b) { put32(b, postings, 7); }, "posting"},
      {"posting count zero", [&](Bytes& b) { put32(b, postings + 4, 0); }, "posting"},
  };
  for (const auto& c : cases) {
    Bytes bad = good;
    c.edit(bad);
    fix_pidx_crc(bad);
    const auto r = PlaceDatabase::load(bad);
    ASSERT_FALSE(r.ok()) << c.what << " accepted";
    EXPECT_EQ(r.status().code(), ErrorCode::kBadData) << c.what;
    EXPECT_NE(r.status().message().find(c.message), std::string::npos) << c.what << ": " << r.status().message();
    EXPECT_TRUE(r.status().offset().has_value()) << c.what;
  }
  // Commit record fields (CRC recomputed so that the field check answers).
  const std::size_t rec = get64(good, 48) == 1 ? 48 : 20;
  {
    Bytes bad = good;
    put64(bad, rec + 8, good.size() + 5);
    fix_commit_crc(bad, rec);
    const auto r = PlaceDatabase::load(bad);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.status().message().find("truncated"), std::string::npos) << r.status().message();
  }
  {
    Bytes bad = good;
    put64(bad, rec + 16, get64(good, rec + 16) - 16);
    fix_commit_crc(bad, rec);
    EXPECT_FALSE(PlaceDatabase::load(bad).ok());
  }
  {
    Bytes bad = good;
    put64(bad, rec, 2);  // an even sequence in the odd slot
    fix_commit_crc(bad, rec);
    const auto r = PlaceDatabase::load(bad);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.status().message().find("commit record"), std::string::npos) << r.status().message();
  }
}

TEST(PlaceFile, CorruptScanIsFoundWhenRead) {
  const Alphabet a = tiny_alphabet(kWords);
  Bytes bad = write_file(3, a);
  auto good = PlaceDatabase::load(bad);
  ASSERT_TRUE(good.ok());
  const auto chunk = good.value().stored_chunk(1);
  ASSERT_TRUE(chunk.ok());
  const auto at = static_cast<std::size_t>(get64(bad, pidx_of(bad).first + 24 + 36));  // entry 1's chunk
  bad[at + 40] ^= 0x10;  // inside scan 1's payload
  auto db = PlaceDatabase::load(bad);
  ASSERT_TRUE(db.ok()) << "scan chunks are not read on open";
  EXPECT_TRUE(db.value().read_scan(0).ok());
  const auto r = db.value().read_scan(1);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("CRC"), std::string::npos) << r.status().message();
  EXPECT_THROW((void)db.value().scan(1), PlaceDataError);
  EXPECT_THROW((void)db.value().save(), PlaceDataError);
  // A query that verifies scan 1 reports it.
  EXPECT_THROW((void)db.value().query(synthetic_scan(1, kWords), PlaceParams{}), PlaceDataError);
}

TEST(PlaceFile, EveryTruncationAndFlipIsRejectedOrHarmless) {
  const Alphabet a = tiny_alphabet(6);
  PlaceFileWriter w(PlaceStorageParams{}, &a, 4);
  Bytes file;
  put_piece(file, w.begin());
  put_piece(file, w.add(synthetic_scan(1, 6)));
  const auto [idx, commit] = w.finish();
  put_piece(file, idx);
  put_piece(file, commit);
  ASSERT_TRUE(PlaceDatabase::load(file).ok());
  for (std::size_t n = 0; n < file.size(); ++n) {
    const Bytes prefix(file.begin(), file.begin() + static_cast<std::ptrdiff_t>(n));
    const auto r = PlaceDatabase::load(prefix);
    ASSERT_FALSE(r.ok()) << "prefix of " << n << " bytes accepted";
    EXPECT_EQ(r.status().code(), ErrorCode::kBadData);
  }
  // Every flipped byte is rejected on open or when the scan is read, except in the commit
  // record that is not in force (a spare copy, ignored when invalid).
  for (std::size_t i = 0; i < file.size(); ++i) {
    Bytes bad = file;
    bad[i] ^= 0x01;
    const auto r = PlaceDatabase::load(bad);
    if (i >= 20 && i < 48) {
      ASSERT_TRUE(r.ok()) << i;
      EXPECT_EQ(r.value().size(), 1U);
      continue;
    }
    EXPECT_TRUE(!r.ok() || !r.value().read_scan(0).ok()) << "flip at byte " << i << " accepted";
  }
  // A newer major version says so.
  Bytes newer = file;
  newer[8] = 3;
  put32(newer, 16, crc_of(newer.data(), 16));
  const auto r = PlaceDatabase::load(newer);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("newer"), std::string::npos) << r.status().message();
}

// A format 1.0 file as the 1.0 writer laid it out (formats/place_db.md §2.2).
Bytes version_1_file(const std::vector<PlaceScan>& scans, const Alphabet& a) {
  Bytes out = {'L', 'E', 'X', '3', 'D', 'P', 'D', 'B', 1, 0, 0, 0, 0, 0, 0, 0};
  out.resize(20);
  put32(out, 16, crc_of(out.data(), 16));
  auto chunk = [&](const char* type, const Bytes& payload) {
    const std::size_t at = out.size();
    out.insert(out.end(), type, type + 4);
    out.resize(out.size() + 8);
    put64(out, at + 4, payload.size());
    out.insert(out.end(), payload.begin(), payload.end());
    out.resize(out.size() + 4);
    put32(out, out.size() - 4, crc_of(out.data() + at, 12 + payload.size()));
  };
  Bytes phdr(32, 0);
  put32(phdr, 0, static_cast<std::uint32_t>(scans.size()));
  phdr[4] = 4;
  phdr[6] = 4;
  phdr[7] = 1;
  put32(phdr, 8, 160);
  double v = 1.5;
  std::memcpy(phdr.data() + 12, &v, 8);
  phdr[20] = 1;
  v = 0.02;
  std::memcpy(phdr.data() + 24, &v, 8);
  chunk("PHDR", phdr);
  chunk("ALPH", codec::encode_alphabet(a));
  for (const auto& s : scans) chunk("SCAN", detail::encode_scan_payload(s, 0.02));
  chunk("PEND", {});
  return out;
}

TEST(PlaceFile, Version1IsReadAndUpgraded) {
  const Alphabet a = tiny_alphabet(kWords);
  std::vector<PlaceScan> scans;
  for (std::uint32_t i = 0; i < 12; ++i) scans.push_back(synthetic_scan(i, kWords));
  const Bytes v1 = version_1_file(scans, a);
  auto db = PlaceDatabase::load(v1);
  ASSERT_TRUE(db.ok()) << db.status().to_string();
  EXPECT_EQ(db.value().file_info().major, 1);
  const PlaceDatabase mem = in_memory(0, 12, a);
  expect_same_retrieval(mem, db.value(), queries());
  for (std::size_t i = 0; i < scans.size(); ++i) expect_same_scan(scans[i], db.value().scan(i));
  // Upgraded: the 2.0 bytes of the same scans.
  const Bytes v2 = db.value().save();
  EXPECT_EQ(v2, mem.save());
  auto up = PlaceDatabase::load(v2);
  ASSERT_TRUE(up.ok());
  EXPECT_EQ(up.value().file_info().major, 2);
  expect_same_retrieval(mem, up.value(), queries());
  // 1.0 is still read strictly: every truncation and every flipped byte is rejected on open.
  for (std::size_t n = 0; n < v1.size(); n += 13) {
    const Bytes prefix(v1.begin(), v1.begin() + static_cast<std::ptrdiff_t>(n));
    EXPECT_FALSE(PlaceDatabase::load(prefix).ok()) << n;
  }
  for (std::size_t i = 0; i < v1.size(); i += 7) {
    Bytes bad = v1;
    bad[i] ^= 0x01;
    EXPECT_FALSE(PlaceDatabase::load(bad).ok()) << "flip at byte " << i << " accepted";
  }
}

// The file path a `place add` takes: mapped for reading, appended through a locked writer,
// reopened; a second writer is refused while the first holds the file.
TEST(PlaceFile, AppendThroughTheFileAndASecondWriterIsRefused) {
  const Alphabet a = tiny_alphabet(kWords);
  const std::string path = (test::temp_dir("place_file") / "db.lex3dp").string();
  ASSERT_TRUE(io::write_file_atomic(path, write_file(5, a)).ok());
  auto writer = io::PositionalFile::open_existing(path);
  ASSERT_TRUE(writer.ok()) << writer.status().to_string();
  auto second = io::PositionalFile::open_existing(path);
  ASSERT_FALSE(second.ok());
  EXPECT_EQ(second.status().code(), ErrorCode::kIoError);
  EXPECT_NE(second.status().message().find("another process"), std::string::npos) << second.status().message();
  {
    auto mapped = io::MappedFile::open(path);
    ASSERT_TRUE(mapped.ok());
    SharedBytes b{mapped.value()->data(), mapped.value()->size(), mapped.value()};
    auto db = PlaceDatabase::open(b);
    ASSERT_TRUE(db.ok()) << db.status().to_string();
    PlaceFileWriter w(db.value());
    auto put = [&](const PlaceFileWriter::Piece& p) { ASSERT_TRUE(writer.value()->write_at(p.offset, p.bytes.data(), p.bytes.size()).ok()); };
    put(w.add(synthetic_scan(5, kWords)));
    const auto [idx, commit] = w.finish();
    put(idx);
    ASSERT_TRUE(writer.value()->sync().ok());
    put(commit);
    ASSERT_TRUE(writer.value()->close().ok());
  }
  auto mapped = io::MappedFile::open(path);
  ASSERT_TRUE(mapped.ok());
  auto db = PlaceDatabase::open({mapped.value()->data(), mapped.value()->size(), mapped.value()});
  ASSERT_TRUE(db.ok()) << db.status().to_string();
  expect_same_retrieval(in_memory(0, 6, a), db.value(), queries());
  EXPECT_TRUE(io::PositionalFile::open_existing(path).ok()) << "the lock goes with the writer";
}

// Balm: a query on the opened file verifies the same candidates, with the same scores
// and transforms, as the scans in memory (the entries decoded lazily are the same).
TEST(PlaceFile, BalmQueriesOnTheFileEqualInMemory) {
  LEX3D_REQUIRE_SHARED("balm/poses.txt");
  auto poses = io::read_pose_list(test::shared_data("balm/poses.txt"));
  ASSERT_TRUE(poses.ok());
  std::vector<PreparedScan> prepared;
  Alphabet alphabet;
  auto place = [&](const std::string& frame) {
    Cloud c = test::load_or_fail(test::shared_data("balm/" + frame + ".bin"));
    c.T_world_cloud = poses.value().at(static_cast<std::size_t>(std::stoi(frame) / 2));
    c.has_world_pose = true;
    const PreparedScan s = prepare_scan(c, ModelParams{}, 0.39);
    if (alphabet.size() == 0) {
      alphabet.descriptor_dim = s.features.descriptor_dim;
      alphabet.word_radius = s.word_radius;
      for (std::size_t i = 0; i < s.features.size(); i += 60) {
        Word w;
        w.descriptor.assign(s.features.descriptor(i), s.features.descriptor(i) + s.features.descriptor_dim);
        alphabet.words.push_back(std::move(w));
      }
    }
    return make_place_scan(s, alphabet, PlaceStorageParams{}, ModelParams{}.features.range, frame);
  };
  const PlaceScan first = place("000000");
  PlaceDatabase mem;
  mem.set_alphabet(alphabet);
  mem.add(first);
  for (const char* f : {"000008", "000080", "000114", "000040"}) mem.add(place(f));
  auto file = PlaceDatabase::load(mem.save());
  ASSERT_TRUE(file.ok()) << file.status().to_string();
  for (const char* f : {"000124", "000176", "000110"}) {
    const PlaceScan q = place(f);
    const auto r1 = mem.query(q, {});
    const auto r2 = file.value().query(q, {});
    ASSERT_EQ(r1.matches.size(), r2.matches.size()) << f;
    EXPECT_EQ(r1.accepted, r2.accepted) << f;
    for (std::size_t i = 0; i < r1.matches.size(); ++i) {
      EXPECT_EQ(r1.matches[i].scan, r2.matches[i].scan) << f;
      EXPECT_EQ(r1.matches[i].score, r2.matches[i].score) << f;
      EXPECT_TRUE(r1.matches[i].T_match_query.isApprox(r2.matches[i].T_match_query, 0.0)) << f;
    }
    if (std::string(f) == "000124") EXPECT_EQ(r2.decoded, r2.retrieved) << "the first query reads every candidate";
    // Asked again, the candidates come from the decoded-scan cache, with the same answer.
    const auto r3 = file.value().query(q, {});
    EXPECT_EQ(r3.decoded, 0U) << f;
    ASSERT_EQ(r3.matches.size(), r2.matches.size());
    for (std::size_t i = 0; i < r2.matches.size(); ++i) {
      EXPECT_EQ(r3.matches[i].scan, r2.matches[i].scan) << f;
      EXPECT_EQ(r3.matches[i].score, r2.matches[i].score) << f;
    }
  }
  // Without the cache every query reads its candidates.
  PlaceDatabase uncached = file.value();
  uncached.set_decoded_cache(0);
  const auto again = uncached.query(place("000124"), {});
  EXPECT_EQ(again.decoded, again.retrieved);
}

// PHDR's descriptor_kind: a VD-LSD database keeps its kind through save and load, takes only
// VD-LSD scans, and an unknown kind or a VD-LSD header with another descriptor size is refused.
TEST(PlaceFile, DescriptorKindIsStoredAndChecked) {
  const Alphabet a = tiny_alphabet(kWords);  // patch descriptors of 4 values
  auto vdlsd_scan = [](std::uint32_t seed) {
    PlaceScan s = synthetic_scan(seed, kWords);
    s.descriptor = PlaceDescriptor::kVdlsd;
    s.descriptor_dim = 64;
    std::mt19937 rng(seed);
    s.descriptor_codes.clear();
    for (std::size_t i = 0; i < s.features.size() * 64; ++i) s.descriptor_codes.push_back(static_cast<std::uint8_t>(rng() % 16));
    detail::finish_place_scan(s);
    return s;
  };
  PlaceStorageParams st;
  st.descriptor = PlaceDescriptor::kVdlsd;
  PlaceDatabase db(st);
  db.set_alphabet(a);
  for (std::uint32_t i = 0; i < 5; ++i) db.add(vdlsd_scan(i));
  EXPECT_THROW(db.add(synthetic_scan(9, kWords)), std::invalid_argument);  // a patch scan
  PlaceDatabase patch_db;
  EXPECT_THROW(patch_db.add(vdlsd_scan(9)), std::invalid_argument);
  const Bytes bytes = db.save();
  auto back = PlaceDatabase::load(bytes);
  ASSERT_TRUE(back.ok()) << back.status().to_string();
  EXPECT_EQ(back.value().storage().descriptor, PlaceDescriptor::kVdlsd);
  EXPECT_EQ(back.value().descriptor_dim(), 64);
  const PlaceScan s0 = back.value().scan(0);
  EXPECT_EQ(s0.descriptor, PlaceDescriptor::kVdlsd);
  expect_same_scan(vdlsd_scan(0), s0);

  // PHDR is the first chunk, at byte 76: type, u64 length, 32 payload bytes, CRC.
  constexpr std::size_t kPhdr = 76, kPayload = kPhdr + 12;
  ASSERT_EQ(std::string(bytes.begin() + kPhdr, bytes.begin() + kPhdr + 4), "PHDR");
  EXPECT_EQ(bytes[kPayload + 22], 1);
  EXPECT_EQ(write_file(3, a)[kPayload + 22], 0);  // a patch database: the bytes as before
  auto with = [&](std::size_t at, std::uint8_t value) {
    Bytes b = bytes;
    b[at] = value;
    put32(b, kPayload + 32, crc_of(b.data() + kPhdr, 12 + 32));
    return PlaceDatabase::load(b);
  };
  const auto unknown = with(kPayload + 22, 2);
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(unknown.status().message().find("unknown descriptor kind 2"), std::string::npos) << unknown.status().to_string();
  const auto wrong_dim = with(kPayload + 4, 100);
  ASSERT_FALSE(wrong_dim.ok());
  EXPECT_NE(wrong_dim.status().message().find("not VD-LSD's 64"), std::string::npos) << wrong_dim.status().to_string();
}

}  // namespace
}  // namespace lex3d
