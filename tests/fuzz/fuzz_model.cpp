// libFuzzer target: lex3d::codec::decode_model (with and without an external alphabet
// file) and inspect. Seeds: tests/fuzz/corpus/. See tests/fuzz/CMakeLists.txt.
#include "fuzz_common.hpp"
#include "libfuzzer_mutator.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  lex3d::fuzz::check_model(data, size);
  return 0;
}
