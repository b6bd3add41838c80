// reader_replay: the reader, place-database and place-query fuzz targets' checks
// (fuzz_readers.hpp, fuzz_place_db.hpp, fuzz_place_query.hpp) for every seed of
// tests/fuzz/readers/<format>/ and then for seeded random mutations of them (bytes, text
// tokens, and the place database's and query's structure-aware mutations). Built with any
// compiler and run by CTest, so every reader's properties are checked on every build, not
// only where libFuzzer exists. A violated property aborts.
//
//   reader_replay [--mutations N] [--seed S] READERS_DIR

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

#include "fuzz_place_db.hpp"
#include "fuzz_place_query.hpp"
#include "fuzz_readers.hpp"

namespace {

namespace fs = std::filesystem;
using lex3d::fuzz::Bytes;

Bytes read_file(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return Bytes(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

/// Inserts or overwrites with a token text parsers must survive (numbers at the edges,
/// header keywords, line breaks).
void mutate_text(Bytes& b, std::mt19937_64& rng) {
  static const char* tokens[] = {"nan",  "inf",    "-inf", "1e308", "-1e38", "4294967296", "-1",     "0",
                                 "\n",   "\r\n",   " ",    ",",     "#",     "99999999999", "1e-320", "0x10",
                                 "DATA ascii\n",   "DATA binary\n", "POINTS 1000000000\n", "WIDTH 0\n",
                                 "element vertex 4000000000\n", "property list uchar int x\n", "end_header\n"};
  const std::string t = tokens[rng() % (sizeof tokens / sizeof *tokens)];
  const std::size_t at = b.empty() ? 0 : rng() % (b.size() + 1);
  if (rng() % 2 == 0 || at + t.size() > b.size())
    b.insert(b.begin() + static_cast<std::ptrdiff_t>(at), t.begin(), t.end());
  else
    std::copy(t.begin(), t.end(), b.begin() + static_cast<std::ptrdiff_t>(at));
}

std::vector<Bytes> seeds_in(const fs::path& dir) {
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.is_regular_file()) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  std::vector<Bytes> out;
  for (const auto& f : files) out.push_back(read_file(f));
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  long mutations = 500;
  unsigned long long seed = 1;
  std::string root;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--mutations" && i + 1 < argc) {
      mutations = std::atol(argv[++i]);
    } else if (arg == "--seed" && i + 1 < argc) {
      seed = std::strtoull(argv[++i], nullptr, 10);
    } else {
      root = arg;
    }
  }
  std::error_code ec;
  if (root.empty() || !fs::is_directory(root, ec)) {
    std::fprintf(stderr, "usage: reader_replay [--mutations N] [--seed S] READERS_DIR\n");
    return 1;
  }
  std::vector<std::string> kinds;
  for (const auto& e : fs::directory_iterator(root))
    if (e.is_directory()) kinds.push_back(e.path().filename().string());
  std::sort(kinds.begin(), kinds.end());
  for (const auto& name : kinds) {
    const bool db = name == "placedb";
    const bool query = name == "placequery";
    const auto* kind = lex3d::fuzz::find_reader(name);
    if (!db && !query && kind == nullptr) {
      std::fprintf(stderr, "reader_replay: %s: no reader of that name\n", name.c_str());
      return 1;
    }
    const auto check = [&](const Bytes& b) {
      if (db)
        lex3d::fuzz::check_place_db(b.data(), b.size());
      else if (query)
        lex3d::fuzz::check_place_query(b.data(), b.size());
      else
        lex3d::fuzz::check_reader(*kind, b.data(), b.size());
    };
    const auto seeds = seeds_in(fs::path(root) / name);
    for (const auto& b : seeds) check(b);
    check(Bytes{});
    std::mt19937_64 rng(seed);
    long n = 0;
    for (; n < mutations && !seeds.empty(); ++n) {
      Bytes b = seeds[rng() % seeds.size()];
      const auto bytes = [&](Bytes& x) { lex3d::fuzz::mutate_bytes(x, rng); };
      switch (rng() % 3) {
        case 0:
          if (db && lex3d::fuzz::mutate_place_db(b, rng, bytes)) break;
          if (query && lex3d::fuzz::mutate_place_query(b, rng, bytes)) break;
          lex3d::fuzz::mutate_bytes(b, rng);
          break;
        case 1: mutate_text(b, rng); break;
        default: lex3d::fuzz::mutate_bytes(b, rng); break;
      }
      check(b);
    }
    std::printf("%-10s %zu seeds, %ld mutations (seed %llu): every property held\n", name.c_str(), seeds.size(), n, seed);
  }
  return 0;
}
