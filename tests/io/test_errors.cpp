// Hardened readers: one test per kind of bad input, each checking the error
// code and that the message names the file on one line; plus truncation and
// corruption sweeps that must never crash.

#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "lex3d/io/io.hpp"
#include "support/test_support.hpp"

namespace lex3d::io {
namespace {

using test::write_bytes;

namespace fs = std::filesystem;
using test::temp_dir;

std::string fixture(const std::string& name) { return std::string(LEX3D_TEST_DATA_DIR) + "/io/" + name; }

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

/// A well-shaped error: the expected code, names the file, one line.
::testing::AssertionResult is_error(const Status& s, ErrorCode code, const std::string& path) {
  if (s.ok()) return ::testing::AssertionFailure() << "expected an error, got ok";
  if (s.code() != code) {
    return ::testing::AssertionFailure() << "code " << static_cast<int>(s.code()) << ", expected "
                                         << static_cast<int>(code) << ": " << s.message();
  }
  const std::string name = fs::path(path).filename().string();
  if (s.message().find(name) == std::string::npos) {
    return ::testing::AssertionFailure() << "message does not name '" << name << "': " << s.message();
  }
  const std::string full = s.to_string();
  if (full.find('\n') != std::string::npos || full.find('\r') != std::string::npos) {
    return ::testing::AssertionFailure() << "message is not one line: " << full;
  }
  return ::testing::AssertionSuccess();
}

/// Writes `bytes` to a file `name` in a fresh directory and reads it; expects kBadData
/// whose message contains `needle`.
void expect_bad(const std::string& test, const std::string& name, const std::string& bytes,
                const std::string& needle, const ReadOptions& o = {}) {
  const auto dir = temp_dir("err_" + test);
  const std::string path = (dir / name).string();
  write_bytes(path, bytes);
  auto r = read_cloud(path, o);
  ASSERT_FALSE(r.ok()) << "read " << name << " unexpectedly succeeded";
  EXPECT_TRUE(is_error(r.status(), ErrorCode::kBadData, path));
  EXPECT_NE(r.status().message().find(needle), std::string::npos)
      << "'" << needle << "' not in: " << r.status().message();
}

std::string pcd_header(const std::string& fields, const std::string& size, const std::string& type,
                       const std::string& width, const std::string& points, const std::string& data) {
  std::string count = "1";
  for (char ch : fields) {
    if (ch == ' ') count += " 1";
  }
  return "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS " + fields + "\nSIZE " + size +
         "\nTYPE " + type + "\nCOUNT " + count +
         "\nWIDTH " + width + "\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " + points + "\nDATA " + data + "\n";
}

const char* kPlyHeader =
    "ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\n"
    "property float y\nproperty float z\nend_header\n";

// ------------------------------------------------------------------ file system

TEST(ReadErrors, MissingFileIsIoError) {
  const auto dir = temp_dir("err_missing");
  const std::string path = (dir / "nothere.pcd").string();
  auto r = read_cloud(path);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(is_error(r.status(), ErrorCode::kIoError, path));
}

TEST(ReadErrors, DirectoryIsIoError) {
  const auto dir = temp_dir("err_dir");
  fs::create_directories(dir / "scan.bin");
  auto r = read_cloud((dir / "scan.bin").string());
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(is_error(r.status(), ErrorCode::kIoError, (dir / "scan.bin").string()));
}

TEST(ReadErrors, EmptyFileInEveryFormat) {
  for (const char* name : {"a.bin", "a.pcd", "a.ply", "a.xyz", "a.3d", "a.unknown"}) {
    SCOPED_TRACE(name);
    expect_bad("empty", name, "", "file is empty");
  }
}

// ------------------------------------------------------------------ float binaries

TEST(ReadErrors, BinSizeNotAMultipleOfRecord) {
  expect_bad("bin13", "000000.bin", std::string(13, '\0'), "size 13 is not a multiple of 16 bytes");
  ReadOptions kitti;
  kitti.format = Format::kKitti;
  expect_bad("bin24", "k.bin", std::string(24, '\0'),
             "size 24 is not a multiple of 16 bytes (KITTI x y z intensity)", kitti);
  ReadOptions xyz;
  xyz.format = Format::kBinXyz;
  expect_bad("bin16", "x.bin", std::string(16, '\0'), "not a multiple of 12 bytes", xyz);
}

// ------------------------------------------------------------------ PCD

TEST(ReadErrors, PcdTruncatedBinary) {
  const std::string h = pcd_header("x y z intensity", "4 4 4 4", "F F F F", "100", "100", "binary");
  expect_bad("pcd_trunc", "cloud.pcd", h + std::string(1200, '\0'),
             "cloud.pcd: truncated binary data: 1200 bytes, header says 1600");
}

TEST(ReadErrors, PcdTruncatedBinaryCompressed) {
  const auto dir = temp_dir("err_pcd_bc_src");
  Cloud c;
  for (int i = 0; i < 200; ++i) c.points.emplace_back(static_cast<float>(i), 0.5F * static_cast<float>(i), 1.0F);
  WriteOptions o;
  o.pcd_encoding = PcdEncoding::kBinaryCompressed;
  const std::string src = (dir / "src.pcd").string();
  ASSERT_TRUE(write_cloud(src, c, o).ok());
  const std::string bytes = slurp(src);
  expect_bad("pcd_bc_trunc", "cloud.pcd", bytes.substr(0, bytes.size() - 5),
             "truncated binary_compressed data");
  const std::size_t data = bytes.find("DATA binary_compressed\n") + 23;
  expect_bad("pcd_bc_nosize", "cloud.pcd", bytes.substr(0, data + 5), "8-byte size header is missing");
  // the size header disagrees with POINTS x point size
  std::string wrong = bytes;
  wrong[data + 4] = static_cast<char>(wrong[data + 4] + 1);
  expect_bad("pcd_bc_wrong", "cloud.pcd", wrong, "header inconsistent");
  // garbage instead of LZF data
  std::string garbage = bytes;
  for (std::size_t i = data + 8; i < garbage.size(); ++i) garbage[i] = static_cast<char>(0xFF);
  expect_bad("pcd_bc_garbage", "cloud.pcd", garbage, "corrupt binary_compressed data");
}

TEST(ReadErrors, PcdHeaderMissingFields) {
  expect_bad("pcd_nofields", "cloud.pcd",
             "VERSION 0.7\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA ascii\n1 2 3\n",
             "header has no FIELDS");
  expect_bad("pcd_nox", "cloud.pcd", pcd_header("a y z", "4 4 4", "F F F", "1", "1", "ascii") + "1 2 3\n",
             "header has no 'x' field");
  expect_bad("pcd_sizes", "cloud.pcd", pcd_header("x y z", "4 4", "F F F", "1", "1", "ascii") + "1 2 3\n",
             "SIZE has 2 entries, FIELDS has 3");
  expect_bad("pcd_type", "cloud.pcd", pcd_header("x y z", "4 4 4", "F Q F", "1", "1", "ascii") + "1 2 3\n",
             "bad TYPE 'Q'");
  expect_bad("pcd_f2", "cloud.pcd", pcd_header("x y z", "4 2 4", "F F F", "1", "1", "ascii") + "1 2 3\n",
             "bad TYPE 'F' for field 'y' of SIZE 2");
  expect_bad("pcd_nodata", "cloud.pcd", "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\n",
             "header has no DATA line");
  expect_bad("pcd_keyword", "cloud.pcd", "VERSION 0.7\nFIELDS x y z\nBOGUS 1\nDATA ascii\n",
             "unknown header keyword 'BOGUS'");
  expect_bad("pcd_encoding", "cloud.pcd", pcd_header("x y z", "4 4 4", "F F F", "1", "1", "zip"),
             "unknown DATA encoding 'zip'");
}

TEST(ReadErrors, PcdBadViewpoint) {
  const std::string head = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nHEIGHT 1\n";
  const std::string tail = "\nPOINTS 1\nDATA ascii\n1 2 3\n";
  for (const char* v : {"0 0 0 1 0 0", "0 0 0 1 0 0 0 0", "0 0 nan 1 0 0 0", "0 0 0 0 0 0 0", "1e12 0 0 1 0 0 0",
                        "0 0 0 1 0 x 0", "0 0 0 3 0 0 0"}) {
    SCOPED_TRACE(v);
    expect_bad("pcd_viewpoint", "cloud.pcd", head + "VIEWPOINT " + v + tail, "VIEWPOINT needs tx ty tz qw qx qy qz");
  }
}

TEST(ReadErrors, PcdBadPoints) {
  expect_bad("pcd_points_text", "cloud.pcd", pcd_header("x y z", "4 4 4", "F F F", "1", "many", "ascii"),
             "POINTS needs one non-negative integer");
  expect_bad("pcd_points_neg", "cloud.pcd", pcd_header("x y z", "4 4 4", "F F F", "1", "-1", "ascii"),
             "POINTS needs one non-negative integer");
  expect_bad("pcd_points_mismatch", "cloud.pcd",
             pcd_header("x y z", "4 4 4", "F F F", "3", "2", "binary") + std::string(36, '\0'),
             "WIDTH 3 x HEIGHT 1 != POINTS 2");
}

TEST(ReadErrors, PcdAbsurdSizes) {
  // 10^12 points claimed by a tiny file: refused before anything is allocated
  expect_bad("pcd_huge", "cloud.pcd",
             pcd_header("x y z", "4 4 4", "F F F", "1000000000000", "1000000000000", "binary") +
                 std::string(64, '\0'),
             "truncated binary data: 64 bytes, header says 12000000000000");
  // WIDTH x HEIGHT overflows 64 bits
  expect_bad("pcd_overflow", "cloud.pcd",
             "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 18446744073709551615\nHEIGHT 3\nDATA binary\n",
             "absurd size");
  // ascii: more points than the bytes could hold
  expect_bad("pcd_huge_ascii", "cloud.pcd",
             pcd_header("x y z", "4 4 4", "F F F", "5000000000", "5000000000", "ascii") + "1 2 3\n",
             "truncated ascii data");
  // binary_compressed claiming to unpack 40 MB from 16 bytes
  std::string bc = pcd_header("x y z", "4 4 4", "F F F", "3500000", "3500000", "binary_compressed");
  const std::uint32_t sizes[2] = {16, 42000000};
  bc.append(reinterpret_cast<const char*>(sizes), 8);
  bc.append(16, '\x01');
  expect_bad("pcd_bc_bomb", "cloud.pcd", bc, "cannot unpack to 42000000");
  // a field COUNT beyond the cap
  expect_bad("pcd_count", "cloud.pcd",
             "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 99999999999\nWIDTH 1\nDATA ascii\n",
             "bad COUNT");
  // a header that never ends: a megabyte of comments
  expect_bad("pcd_long_header", "cloud.pcd", "VERSION 0.7\n" + std::string(1U << 21, '#'),
             "no DATA line in the first 1048576 bytes");
}

TEST(ReadErrors, PcdAsciiLineNotNumbers) {
  expect_bad("pcd_ascii_nan", "cloud.pcd",
             pcd_header("x y z", "4 4 4", "F F F", "2", "2", "ascii") + "1 2 3\n4 five 6\n",
             "line 13: 'five' is not a number");
  expect_bad("pcd_ascii_short", "cloud.pcd",
             pcd_header("x y z", "4 4 4", "F F F", "2", "2", "ascii") + "1 2 3\n4 5      \n",
             "line 13: expected 3 values, found 2");
  expect_bad("pcd_ascii_few", "cloud.pcd",
             pcd_header("x y z", "4 4 4", "F F F", "3", "3", "ascii") + "1 2 3\n4 5 6\n",
             "truncated ascii data");
}

// ------------------------------------------------------------------ PLY

TEST(ReadErrors, PlyWithoutEndHeader) {
  expect_bad("ply_noend", "x.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n",
             "x.ply: header has no 'end_header'");
  expect_bad("ply_noend_long", "x.ply", "ply\nformat ascii 1.0\n" + std::string(1U << 21, ' '),
             "header has no 'end_header' in the first");
}

TEST(ReadErrors, PlyTruncatedBinary) {
  expect_bad("ply_trunc", "x.ply", std::string(kPlyHeader) + std::string(100, '\0'),
             "truncated binary data: 100 bytes left for 10 vertices of 12 bytes");
  // truncated inside an element before the vertices
  expect_bad("ply_trunc_face", "x.ply",
             "ply\nformat binary_little_endian 1.0\nelement face 3\nproperty list uchar int idx\n"
             "element vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n" +
                 std::string("\x03\x01\x00\x00\x00", 5),
             "truncated binary data: element 'face' item 0 of 3");
}

TEST(ReadErrors, PlyMalformedHeader) {
  struct BadPly {
    const char* test;
    std::string bytes;
    const char* needle;
  };
  const BadPly cases[] = {
      {"ply_format", "ply\nformat binary_middle_endian 1.0\nend_header\n",
       "unknown format 'binary_middle_endian'"},
      {"ply_noformat", "ply\nelement vertex 0\nproperty float x\nend_header\n",
       "header has no 'format' line"},
      {"ply_novertex", "ply\nformat ascii 1.0\nelement face 0\nend_header\n",
       "header has no 'vertex' element"},
      {"ply_noz",
       "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n",
       "vertex element has no 'z' property"},
      {"ply_type", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n",
       "unknown property type 'float128'"},
      {"ply_prop_first", "ply\nformat ascii 1.0\nproperty float x\nend_header\n",
       "property before any element"},
      {"ply_count", "ply\nformat ascii 1.0\nelement vertex -5\nend_header\n",
       "element needs a name and a non-negative count"},
      {"ply_huge",
       "ply\nformat binary_little_endian 1.0\nelement vertex 99999999999999\nproperty float x\n"
       "property float y\nproperty float z\nend_header\n" + std::string(24, '\0'),
       "truncated binary data"},
  };
  for (const BadPly& c : cases) {
    SCOPED_TRACE(c.test);
    expect_bad(c.test, "x.ply", c.bytes, c.needle);
  }
}

TEST(ReadErrors, PlyAsciiNotNumbers) {
  expect_bad("ply_ascii", "x.ply",
             "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
             "end_header\n1 2 3\n4 5 oops\n",
             "line 9: 'oops' is not a number");
  expect_bad("ply_ascii_short", "x.ply",
             "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
             "end_header\n1 2 3\n4 5\n",
             "truncated ascii data");
}

// ------------------------------------------------------------------ text and .3d

TEST(ReadErrors, TextLineThatIsNotNumbers) {
  const auto dir = temp_dir("err_text");
  const std::string path = (dir / "points.xyz").string();
  write_bytes(path, "1 2 3\n4 5 six\n7 8 9\n");
  auto r = read_cloud(path);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(is_error(r.status(), ErrorCode::kBadData, path));
  EXPECT_NE(r.status().message().find("line 2: 'six' is not a number"), std::string::npos)
      << r.status().message();
  ASSERT_TRUE(r.status().offset().has_value());
  EXPECT_EQ(*r.status().offset(), 6U);

  expect_bad("text_cols", "p.txt", "1 2 3\n1 2 3 4\n", "line 2: 4 values, but line 1 has 3");
  expect_bad("text_two", "p.txt", "1 2\n", "line 1: expected at least 3 numbers");
  expect_bad("text_binary", "p.xyz", std::string("1 2 3\n\0\0\0", 9), "NUL byte");
  expect_bad("text_control", "p.xyz", "1 2 3\n\x01\x02\xff 4 5\n", "line 2: '\?\?\?' is not a number");
}

TEST(ReadErrors, Uos3dWithGarbage) {
  expect_bad("uos_garbage", "scan.3d", "100 0 0\n200 0 0\nhello world and more\n", "line 3: 'hello'");
  expect_bad("uos_binary", "scan.3d", std::string("\x7f" "ELF\x02\x01\x01\0\0\0", 10), "NUL byte");
}

TEST(ReadErrors, Uos3dWithBadPoseFile) {
  const auto dir = temp_dir("err_uos_pose");
  write_bytes((dir / "scan.3d").string(), "100 0 0\n");
  write_bytes((dir / "scan.pose").string(), "1 2 3\nx y z\n");
  auto r = read_cloud((dir / "scan.3d").string());
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(is_error(r.status(), ErrorCode::kBadData, (dir / "scan.pose").string()));
  write_bytes((dir / "scan.pose").string(), "1 2 3\n");
  r = read_cloud((dir / "scan.3d").string());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("expected two lines"), std::string::npos);
  ReadOptions o;
  o.load_pose = false;
  EXPECT_TRUE(read_cloud((dir / "scan.3d").string(), o).ok());
}

TEST(ReadErrors, UnknownFormat) {
  expect_bad("unknown", "cloud.e57", std::string("ASTM\x01\x02\x03", 7), "cannot tell the format");
  expect_bad("las_short", "cloud.las", std::string("LASF\x01\x02\x03", 7), "truncated LAS header");
  expect_bad("las_magic", "cloud.las", std::string("LASX\x01\x02\x03", 7), "LASF");
  expect_bad("laz", "cloud.laz", std::string("LASF\x01\x02\x03", 7), "LAZ");
}

// ------------------------------------------------------------------ lists

TEST(ListErrors, PoseList) {
  const auto dir = temp_dir("err_poses");
  const std::string path = (dir / "poses.txt").string();
  const std::string ok = "1 0 0 0 0 1 0 0 0 0 1 0\n";
  auto expect = [&](const std::string& content, ErrorCode code, const std::string& needle) {
    write_bytes(path, content);
    auto r = read_pose_list(path);
    ASSERT_FALSE(r.ok()) << content;
    EXPECT_TRUE(is_error(r.status(), code, path));
    EXPECT_NE(r.status().message().find(needle), std::string::npos) << r.status().message();
  };
  expect(ok + "\n" + ok, ErrorCode::kBadData, "line 2: blank line");
  expect(ok + "1 0 0 0 0 1 0 0 0 0 1\n", ErrorCode::kBadData, "line 2: expected 12 numbers");
  expect("2 0 0 0 0 2 0 0 0 0 2 0\n", ErrorCode::kBadData, "line 1: not a rotation");
  expect("-1 0 0 0 0 1 0 0 0 0 1 0\n", ErrorCode::kBadData, "line 1: not a rotation");  // a reflection
  expect("1 0 0 0 0 1 0 0 0 0 1 zero\n", ErrorCode::kBadData, "'zero' is not a number");
  expect("1 0 0 0 0 1 0 0 0 0 1 nan\n", ErrorCode::kBadData, "NaN");
  expect("", ErrorCode::kBadData, "file is empty");
  auto missing = read_pose_list((dir / "none.txt").string());
  EXPECT_TRUE(is_error(missing.status(), ErrorCode::kIoError, (dir / "none.txt").string()));
}

TEST(ListErrors, NumberList) {
  const auto dir = temp_dir("err_numbers");
  const std::string path = (dir / "times.txt").string();
  write_bytes(path, "0.1\n0.2 0.3\n");
  auto r = read_number_list(path);
  EXPECT_TRUE(is_error(r.status(), ErrorCode::kBadData, path));
  write_bytes(path, "0.1\nabc\n");
  r = read_number_list(path);
  EXPECT_TRUE(is_error(r.status(), ErrorCode::kBadData, path));
  EXPECT_NE(r.status().message().find("line 2"), std::string::npos);
  auto missing = read_number_list((dir / "none.txt").string());
  EXPECT_TRUE(is_error(missing.status(), ErrorCode::kIoError, (dir / "none.txt").string()));
}

// ------------------------------------------------------------------ sweeps

/// Small valid files of each binary-ish kind: (file name, bytes).
std::vector<std::pair<std::string, std::string>> sweep_inputs() {
  const auto dir = temp_dir("sweep_src");
  Cloud c;
  for (int i = 0; i < 24; ++i) {
    c.points.emplace_back(0.25F * static_cast<float>(i), -1.0F + static_cast<float>(i % 5), 3.0F);
    c.intensity.push_back(static_cast<float>(i % 7));
  }
  WriteOptions colours;
  for (int i = 0; i < 24; ++i) {
    colours.colors.push_back({static_cast<std::uint8_t>(i), 2, static_cast<std::uint8_t>(200 - i)});
  }
  std::vector<std::pair<std::string, std::string>> out;
  auto add = [&](const std::string& name, WriteOptions o) {
    const std::string p = (dir / name).string();
    EXPECT_TRUE(write_cloud(p, c, o).ok());
    out.emplace_back(name, slurp(p));
  };
  WriteOptions o = colours;
  o.pcd_encoding = PcdEncoding::kBinaryCompressed;
  add("bc.pcd", o);
  o.pcd_encoding = PcdEncoding::kBinary;
  add("bin.pcd", o);
  o.pcd_encoding = PcdEncoding::kAscii;
  add("ascii.pcd", o);
  o = colours;
  o.ply_binary = true;
  add("bin.ply", o);
  o.ply_binary = false;
  add("ascii.ply", o);
  add("scan.bin", WriteOptions{});
  add("pts.xyz", WriteOptions{});
  for (const char* f : {"big_endian.ply", "extra_props_double.ply", "organized_nan.pcd", "tiny.3d"}) {
    out.emplace_back(f, slurp(fixture(f)));
  }
  return out;
}

TEST(ReadSweep, EveryPrefixIsReadOrRejectedCleanly) {
  const auto dir = temp_dir("sweep");
  for (const auto& [name, bytes] : sweep_inputs()) {
    SCOPED_TRACE(name);
    ASSERT_FALSE(bytes.empty());
    const std::string path = (dir / name).string();
    std::size_t errors = 0;
    for (std::size_t len = 0; len < bytes.size(); ++len) {
      write_bytes(path, bytes.substr(0, len));
      ReadOptions o;
      o.load_pose = false;
      auto r = read_cloud(path, o);
      if (!r.ok()) {
        ++errors;
        ASSERT_TRUE(is_error(r.status(), ErrorCode::kBadData, path)) << "prefix " << len;
      }
    }
    EXPECT_GT(errors, 0U);
    write_bytes(path, bytes);
    EXPECT_TRUE(read_cloud(path).ok());
  }
}

TEST(ReadSweep, RandomCorruptionNeverCrashes) {
  const auto dir = temp_dir("corrupt");
  std::mt19937 rng(12345);
  for (const auto& [name, bytes] : sweep_inputs()) {
    SCOPED_TRACE(name);
    const std::string path = (dir / name).string();
    for (int trial = 0; trial < 300; ++trial) {
      std::string b = bytes;
      const int flips = 1 + static_cast<int>(rng() % 4);
      for (int k = 0; k < flips; ++k) {
        const std::size_t at = rng() % b.size();
        b[at] = static_cast<char>(rng() & 0xFF);
      }
      write_bytes(path, b);
      ReadOptions o;
      o.load_pose = false;
      auto r = read_cloud(path, o);
      if (!r.ok()) {
        ASSERT_NE(r.status().code(), ErrorCode::kOk);
        ASSERT_EQ(r.status().to_string().find('\n'), std::string::npos) << r.status().to_string();
      }
    }
  }
}

}  // namespace
}  // namespace lex3d::io
