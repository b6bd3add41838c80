// libFuzzer target: lex3d::codec::decode_alphabet, inspect, and the alphabet as the
// external alphabet file of a referencing model. Seeds: tests/fuzz/corpus/.
#include "fuzz_common.hpp"
#include "libfuzzer_mutator.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  lex3d::fuzz::check_alphabet(data, size);
  return 0;
}
