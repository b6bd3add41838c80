// libFuzzer target for one input reader, chosen by the executable's name
// (fuzz_reader_<format>, e.g. fuzz_reader_pcd; fuzz_readers.hpp lists the formats), so the
// targets share one build. Seeds: tests/fuzz/readers/<format>/ (make_reader_corpus.py).
// See tests/fuzz/CMakeLists.txt.
#include <string>

#include "fuzz_readers.hpp"

#ifdef LEX3D_WITH_ROSBAG
#include <rosbag/bag.h>
#endif

namespace {
const lex3d::fuzz::ReaderKind* g_kind = nullptr;

#ifdef LEX3D_WITH_ROSBAG
/// Every bag the reader opens loads the ROS bag library's encryptor plugin and unloads it
/// when it closes (a dlopen and a dlclose, most of the time an input takes): one bag held
/// open for the process's life keeps the plugin loaded.
void keep_bag_plugin_loaded() {
  static auto* bag = new rosbag::Bag;  // never closed
  try {
    bag->open(lex3d::fuzz::scratch_dir() + "/keep.bag", rosbag::bagmode::Write);
  } catch (const std::exception& e) {
    lex3d::fuzz::reader_fail("cannot open a bag for writing", e.what());
  }
}
#endif
}  // namespace

extern "C" int LLVMFuzzerInitialize(int* argc, char*** argv) {
  std::string name = *argc > 0 ? (*argv)[0] : "";
  name = name.substr(name.find_last_of('/') + 1);
  const std::string prefix = "fuzz_reader_";
  if (name.rfind(prefix, 0) == 0) g_kind = lex3d::fuzz::find_reader(name.substr(prefix.size()));
  if (g_kind == nullptr) lex3d::fuzz::reader_fail("the executable's name names no reader", name);
#ifdef LEX3D_WITH_ROSBAG
  if (g_kind->reader == lex3d::fuzz::Reader::kBag) keep_bag_plugin_loaded();
#endif
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  lex3d::fuzz::check_reader(*g_kind, data, size);
  return 0;
}
