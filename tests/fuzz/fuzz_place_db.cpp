// libFuzzer target: the place database loader (PlaceDatabase::load, read_scan, retrieve,
// save). Seeds: tests/fuzz/readers/placedb/. See tests/fuzz/CMakeLists.txt.
#include "fuzz_place_db.hpp"

#define LEX3D_FUZZ_MUTATE_STRUCTURE lex3d::fuzz::mutate_place_db
#include "libfuzzer_mutator.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  lex3d::fuzz::check_place_db(data, size);
  return 0;
}
