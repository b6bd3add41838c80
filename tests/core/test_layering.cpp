// The module dependency order of docs/architecture.md, checked on the sources so
// that it cannot erode silently: a module may include only the modules it
// depends on, and only io (and later codec) may touch files.

#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "test_config.hpp"

namespace fs = std::filesystem;

namespace {

const std::map<std::string, std::set<std::string>>& allowed() {
  static const std::map<std::string, std::set<std::string>> table = {
      {"core", {"core"}},
      {"io", {"core", "io"}},
      {"range", {"core", "range"}},
      {"features", {"core", "range", "features"}},
      {"alphabet", {"core", "range", "features", "alphabet"}},
      {"model", {"core", "range", "features", "alphabet", "model"}},
      {"codec", {"core", "range", "features", "alphabet", "model", "codec"}},
      {"residual", {"core", "range", "features", "alphabet", "model", "codec", "residual"}},
      {"place", {"core", "range", "features", "alphabet", "model", "codec", "place"}},
      {"eval", {"core", "eval"}},
      {"api", {"core", "range", "features", "alphabet", "model", "codec", "residual", "api"}},
  };
  return table;
}

std::string read_all(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

fs::path source_root() { return fs::path(LEX3D_TEST_DATA_DIR).parent_path().parent_path(); }

}  // namespace

TEST(Layering, ModulesIncludeOnlyWhatTheyDependOn) {
  const std::regex inc(R"(#include\s+["<]lex3d/([a-z_]+)/)");
  std::size_t files = 0;
  for (const char* top : {"include/lex3d", "src"}) {
    const fs::path root = source_root() / top;
    ASSERT_TRUE(fs::exists(root)) << root;
    for (const auto& entry : fs::recursive_directory_iterator(root)) {
      if (!entry.is_regular_file()) continue;
      const fs::path rel = fs::relative(entry.path(), root);
      // The headers directly under include/lex3d (lex3d.hpp) front the api module.
      const std::string module = rel.has_parent_path() ? rel.begin()->string() : "api";
      const auto it = allowed().find(module);
      ASSERT_NE(it, allowed().end()) << "module '" << module << "' missing from the layering table";
      const std::string text = read_all(entry.path());
      ++files;
      for (std::sregex_iterator m(text.begin(), text.end(), inc), end; m != end; ++m)
        EXPECT_TRUE(it->second.count((*m)[1].str()))
            << entry.path() << " (" << module << ") includes lex3d/" << (*m)[1].str();
    }
  }
  EXPECT_GT(files, 10U);
}

TEST(Layering, OnlyIoTouchesFiles) {
  const std::regex file_api(R"(#include\s+<(fstream|cstdio)>|\bfopen\s*\()");
  const fs::path root = source_root() / "src";
  for (const auto& entry : fs::recursive_directory_iterator(root)) {
    if (!entry.is_regular_file()) continue;
    const std::string module = fs::relative(entry.path(), root).begin()->string();
    if (module == "io" || module == "codec") continue;
    const std::string text = read_all(entry.path());
    EXPECT_FALSE(std::regex_search(text, file_api)) << entry.path() << " uses file I/O outside io/codec";
  }
}
