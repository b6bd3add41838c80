// libFuzzer target: the prepared place query (decode_place_query, encode_place_query).
// Seeds: tests/fuzz/readers/placequery/. See tests/fuzz/CMakeLists.txt.
#include "fuzz_place_query.hpp"

#define LEX3D_FUZZ_MUTATE_STRUCTURE lex3d::fuzz::mutate_place_query
#include "libfuzzer_mutator.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  lex3d::fuzz::check_place_query(data, size);
  return 0;
}
