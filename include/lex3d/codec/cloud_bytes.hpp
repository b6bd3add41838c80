#pragma once
/// \file
/// A Cloud as bytes and back, whole: positions, every per-point attribute and named field,
/// the sensor geometry, the georeference with its CRS records, the stamp, the poses and the
/// range-image shape. For handing a scan to another process (a pickled lex3d.Scan, a Dask
/// task), not for storing it: the layout carries a version and may change between lex3d
/// versions (model files, formats/model.md, are the stored form).

#include <cstddef>
#include <cstdint>
#include <vector>

#include "lex3d/core/cloud.hpp"
#include "lex3d/core/status.hpp"

#pragma GCC visibility push(default)

namespace lex3d::codec {

/// `cloud` as bytes (cloud_from_bytes gives it back equal, member for member).
[[nodiscard]] std::vector<std::uint8_t> cloud_to_bytes(const Cloud& cloud);

/// The cloud of bytes that cloud_to_bytes wrote. Bytes that are not such a cloud (another
/// version, truncated, a count beyond the bytes, a per-point array whose length is neither 0
/// nor the points') give kBadData with one line saying what is wrong; nothing is allocated
/// beyond what the bytes hold.
[[nodiscard]] StatusOr<Cloud> cloud_from_bytes(const std::uint8_t* data, std::size_t size);

}  // namespace lex3d::codec

#pragma GCC visibility pop
