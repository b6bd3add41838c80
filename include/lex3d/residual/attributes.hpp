#pragma once
/// \file
/// Point attributes of a model file (formats/model.md §2.10, the `ATTR` chunk): the
/// intensity, laser (ring), time and colour of every decoded point, range coded in the
/// decoded order with the residual layer's range coder.
///
/// A decoded point takes the attributes of the input point it stands for (`sources`):
/// a point coded by the residual layer, the input point it was quantised from; a kept
/// word point or a voxel centre, the input point nearest to it (ties: the lowest index).
/// Intensity is lossless by default: its values are coded as integers times a step
/// derived from the data (KITTI's 0.01, a sensor's integer counts), or, when no step
/// reproduces every value exactly, as their float32 bit patterns.

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "lex3d/core/cloud.hpp"
#include "lex3d/core/status.hpp"

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d::residual {

/// Each decoded point's place in a sensor-geometry residual layer (formats/model.md §2.8):
/// its laser in the layer's table and its column in the table's grid, the attribute
/// coder's keys (§2.10, methods 3, 4 and 6). A kept word point has the table's laser count
/// as its laser and `columns` as its column. Empty for the other codings.
struct LayerKeys {
  std::vector<std::uint16_t> laser;
  std::vector<std::uint32_t> column;
  std::uint32_t columns = 0;  ///< the grid's columns a turn
  [[nodiscard]] bool empty() const noexcept { return laser.empty(); }
  void clear() {
    laser = {};
    column = {};
    columns = 0;
  }
};

/// Which attributes the encoder keeps (those the input has), and how.
struct AttributeOptions {
  bool intensity = true;  ///< keep Cloud::intensity
  bool time = true;       ///< keep Cloud::time
  bool ring = true;       ///< keep Cloud::ring
  bool rgb = true;        ///< keep Cloud::rgb
  bool fields = true;     ///< keep Cloud::fields (named integer fields, lossless)
  /// Fields not kept, by name: "ring", "intensity", "time", "rgb" or a named field's.
  std::vector<std::string> drop;
  /// Largest intensity error, in the intensity's units; 0: lossless. [0, 1e9].
  double intensity_error = 0.0;
  /// Largest time error, seconds, when the times have no exact step; (0, 1].
  double time_error = 0.5e-9;
  /// Sensor-rate encoding (residual::LayerOptions::fast): on many points, a field's methods
  /// are compared on a quarter of them and only the smallest there is coded in full (by
  /// default each is coded in full and the smallest kept).
  bool fast = false;
  void validate() const;
};

/// One coded field, as `lex3d info` and `compress` report it.
struct AttributeField {
  std::string name;            ///< "intensity", "time", "ring", "rgb", or a named field's name
  std::string representation;  ///< e.g. "step 0.01", "float32 bits", "step 1e-09 from 1.2e9"
  double step = 0.0;           ///< quantisation step (0 for float32 bits)
  double max_error = 0.0;      ///< 0: lossless
  std::size_t bytes = 0;       ///< stored bytes of the field (descriptor and stream)
  /// 0: context tree; 1: previous value; 2: linear; 3: previous value of the same laser of
  /// the sensor-geometry layer; 4: mixed tree on the same laser of that layer; 5: mixed tree;
  /// 6: the value of the same measurement column of that layer (a raw log's firing times)
  std::uint8_t method = 0;
};

/// Encodes the `ATTR` payload for the decoded points: `sources[j]` is the input point
/// decoded point j stands for. Fields kept: those of `options` the input has. Throws
/// std::invalid_argument naming the field for a non-finite value, a field whose size is
/// neither 0 nor the point count, a named field whose name is not 1-64 letters, digits or
/// underscores, repeats, or whose values span more than 2^31, or a source index beyond the
/// input. An empty result
/// (no field to keep) means no chunk. `layer`: with a sensor-geometry residual layer, each
/// decoded point's laser and column (LayerStats::layer), which lets a field be coded
/// against the last value of the same laser (method 3; a ring that is a function of the
/// table's laser then costs next to nothing), by a context tree on it (method 4), or
/// against the value of the same measurement column (method 6: a time that is its
/// firing's); empty otherwise. `threads`: the methods tried side by side (the bytes do not
/// depend on it).
[[nodiscard]] std::vector<std::uint8_t> encode_attributes(const Cloud& input, const std::vector<std::uint32_t>& sources,
                                                          const AttributeOptions& options = {},
                                                          std::vector<AttributeField>* fields = nullptr,
                                                          const LayerKeys& layer = {}, int threads = 1);

/// The fields of an `ATTR` payload (descriptors only; the streams are not decoded).
[[nodiscard]] StatusOr<std::vector<AttributeField>> inspect_attributes(const std::vector<std::uint8_t>& payload);

/// Decodes an `ATTR` payload onto `decoded` (the decoded cloud, whose size the payload
/// must match): sets its intensity, time, ring, rgb and named fields as the payload holds them.
/// kBadData with the payload offset on a malformed or truncated payload, and for a field
/// coded against the sensor-geometry layer's lasers (methods 3 and 4), which only decode_cloud
/// can decode.
[[nodiscard]] Status decode_attributes(const std::vector<std::uint8_t>& payload, Cloud& decoded);

}  // namespace lex3d::residual

#pragma GCC visibility pop
