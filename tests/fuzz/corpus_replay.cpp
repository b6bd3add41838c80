// fuzz_corpus_replay: the fuzz targets' checks (fuzz_common.hpp) for every file of the
// given corpus directories (or files), then for seeded random mutations of them, plain
// and structure-aware (fuzz_mutate.hpp). Built with any compiler and run by CTest, so
// the corpus and the decoders' properties are checked on every build, not only where
// libFuzzer exists. Exit 0 when every input passed; a violated property aborts.
//
//   fuzz_corpus_replay [--mutations N] [--seed S] PATH...

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

#include "fuzz_common.hpp"
#include "fuzz_mutate.hpp"

namespace {

lex3d::fuzz::Bytes read_file(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return lex3d::fuzz::Bytes(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

void check(const lex3d::fuzz::Bytes& b) {
  lex3d::fuzz::check_model(b.data(), b.size());
  lex3d::fuzz::check_alphabet(b.data(), b.size());
}

}  // namespace

int main(int argc, char** argv) {
  namespace fs = std::filesystem;
  long mutations = 4000;
  unsigned long long seed = 1;
  std::vector<fs::path> files;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--mutations" && i + 1 < argc) {
      mutations = std::atol(argv[++i]);
      continue;
    }
    if (arg == "--seed" && i + 1 < argc) {
      seed = std::strtoull(argv[++i], nullptr, 10);
      continue;
    }
    std::error_code ec;
    if (fs::is_directory(arg, ec)) {
      std::vector<fs::path> in_dir;
      for (const auto& e : fs::directory_iterator(arg))
        if (e.is_regular_file()) in_dir.push_back(e.path());
      std::sort(in_dir.begin(), in_dir.end());
      files.insert(files.end(), in_dir.begin(), in_dir.end());
    } else if (fs::is_regular_file(arg, ec)) {
      files.emplace_back(arg);
    } else {
      std::fprintf(stderr, "fuzz_corpus_replay: no such file or directory: %s\n", arg.c_str());
      return 1;
    }
  }
  if (files.empty()) {
    std::fprintf(stderr, "usage: fuzz_corpus_replay [--mutations N] [--seed S] CORPUS_DIR_OR_FILE...\n");
    return 1;
  }

  std::vector<lex3d::fuzz::Bytes> bases;
  for (const auto& f : files) {
    const auto b = read_file(f);
    check(b);
    if (!b.empty()) bases.push_back(b);
  }
  std::printf("replayed %zu corpus files\n", files.size());

  std::mt19937_64 rng(seed);
  long structured = 0;
  long decoded = 0;
  for (long i = 0; i < mutations && !bases.empty(); ++i) {
    lex3d::fuzz::Bytes b = bases[rng() % bases.size()];
    const auto byte_mutator = [&](lex3d::fuzz::Bytes& x) { lex3d::fuzz::mutate_bytes(x, rng); };
    if (rng() % 3 != 0 && lex3d::fuzz::mutate_structure(b, rng, byte_mutator))
      ++structured;
    else
      lex3d::fuzz::mutate_bytes(b, rng);
    check(b);
    if (lex3d::codec::decode_model(b, &lex3d::fuzz::external_alphabet()).ok() || lex3d::codec::decode_alphabet(b).ok())
      ++decoded;
  }
  std::printf("checked %ld mutations (%ld structure-aware, seed %llu): %ld still decode, the rest were rejected cleanly\n",
              mutations, structured, seed, decoded);
  return 0;
}
