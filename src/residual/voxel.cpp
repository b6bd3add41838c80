// Octree occupancy coding of the voxel residual layer (src/residual/voxel.hpp,
// formats/model.md §2.7).

#include "residual/voxel.hpp"

#include "residual/mixing.hpp"

#include <algorithm>
#include <array>
#include <memory>

namespace lex3d::residual::detail {
namespace {

// The bits of x, y and z in a Morton code.
constexpr std::uint64_t kAxisBits[3] = {0x1249249249249249ULL, 0x2492492492492492ULL, 0x4924924924924924ULL};

std::uint64_t spread(std::uint32_t v) {
  std::uint64_t x = v & 0x1FFFFFU;
  x = (x | x << 32) & 0x1F00000000FFFFULL;
  x = (x | x << 16) & 0x1F0000FF0000FFULL;
  x = (x | x << 8) & 0x100F00F00F00F00FULL;
  x = (x | x << 4) & 0x10C30C30C30C30C3ULL;
  x = (x | x << 2) & 0x1249249249249249ULL;
  return x;
}

std::uint32_t compact(std::uint64_t x) {
  x &= 0x1249249249249249ULL;
  x = (x ^ (x >> 2)) & 0x10C30C30C30C30C3ULL;
  x = (x ^ (x >> 4)) & 0x100F00F00F00F00FULL;
  x = (x ^ (x >> 8)) & 0x1F0000FF0000FFULL;
  x = (x ^ (x >> 16)) & 0x1F00000000FFFFULL;
  x = (x ^ (x >> 32)) & 0x1FFFFFULL;
  return static_cast<std::uint32_t>(x);
}

/// The occupied nodes of one level, for "which face neighbours of this node are
/// occupied?". Nodes are grouped in blocks of 4x4x4 (a Morton code's low six bits are the
/// place in its block), each held as a 64-bit mask; a block's six face-neighbour blocks
/// are looked up once (open addressing), so a node's neighbours cost a few bit operations
/// rather than six scattered table probes.
class LevelOccupancy {
 public:
  /// `nodes`: the level's occupied nodes, sorted.
  void assign(const std::vector<std::uint64_t>& nodes) {
    keys_.clear();
    masks_.clear();
    first_.clear();
    for (std::uint32_t k = 0; k < nodes.size(); ++k) {
      const std::uint64_t n = nodes[k];
      if (keys_.empty() || keys_.back() != (n >> 6)) {
        keys_.push_back(n >> 6);
        masks_.push_back(0);
        first_.push_back(k);
      }
      masks_.back() |= 1ULL << (n & 63U);
    }
    std::size_t cap = 16;
    while (cap < 2 * keys_.size()) cap <<= 1;
    slots_.assign(cap, kNone);
    mask_ = cap - 1;
    for (std::uint32_t b = 0; b < keys_.size(); ++b) {
      std::size_t i = hash(keys_[b]) & mask_;
      while (slots_[i] != kNone) i = (i + 1) & mask_;
      slots_[i] = b;
    }
    around_.assign(6 * keys_.size(), kNone);
    for (std::size_t b = 0; b < keys_.size(); ++b)
      for (int a = 0; a < 3; ++a) {
        const std::uint64_t axis = kAxisBits[a] >> 6;  // the axis' bits of a block key
        const std::uint64_t own = keys_[b] & axis, rest = keys_[b] & ~axis;
        if (own != 0) around_[6 * b + 2 * a] = block_of((((own - 1) & axis) | rest));
        around_[6 * b + 2 * a + 1] = block_of((((own | ~axis) + 1) & axis) | rest);
      }
  }
  [[nodiscard]] std::size_t blocks() const noexcept { return keys_.size(); }
  [[nodiscard]] std::uint64_t key(std::size_t b) const noexcept { return keys_[b]; }

  /// Which of the six face neighbours of `node` (in block b) are occupied: bit 2a for the
  /// one below along axis a, bit 2a+1 above. (Nodes beyond the level's extent are never
  /// occupied, so no bounds are needed.)
  [[nodiscard]] unsigned neighbours(std::size_t b, std::uint64_t node) const noexcept {
    const unsigned local = static_cast<unsigned>(node & 63U);
    unsigned ctx = 0;
    for (int a = 0; a < 3; ++a) {
      const unsigned axis = 9U << a;  // bits a and a + 3: the axis' coordinate in the block
      const unsigned own = local & axis, rest = local & ~axis;
      // Below: inside the block unless the coordinate is 0, then the far side of the block below.
      const std::uint64_t below = own != 0 ? masks_[b] >> (((own - 1) & axis) | rest)
                                           : mask(around_[6 * b + 2 * a]) >> (axis | rest);
      const std::uint64_t above = own != axis ? masks_[b] >> ((((own | ~axis) + 1) & axis) | rest)
                                              : mask(around_[6 * b + 2 * a + 1]) >> rest;
      ctx |= static_cast<unsigned>(below & 1U) << (2 * a);
      ctx |= static_cast<unsigned>(above & 1U) << (2 * a + 1);
    }
    return ctx;
  }

  /// low[a]: the occupancy byte of the node one step lower than `node` (in block b) along
  /// axis a, 0 when it is not occupied. `bytes`: the bytes of the level's nodes in order,
  /// at least up to `node` (the lower neighbours come earlier in Morton order).
  void lower_bytes(std::size_t b, std::uint64_t node, const std::vector<std::uint8_t>& bytes,
                   unsigned low[3]) const noexcept {
    for (int a = 0; a < 3; ++a) {
      const std::int64_t at = lower(b, node, a);
      low[a] = at >= 0 ? bytes[static_cast<std::size_t>(at)] : 0U;
    }
  }

 private:
  /// Where in the level's node order the node one step lower than `node` (in block b)
  /// along axis a stands; -1 when that node is not occupied.
  [[nodiscard]] std::int64_t lower(std::size_t b, std::uint64_t node, int a) const noexcept {
    const unsigned local = static_cast<unsigned>(node & 63U);
    const unsigned axis = 9U << a;
    const unsigned own = local & axis, rest = local & ~axis;
    const std::uint32_t block = own != 0 ? static_cast<std::uint32_t>(b) : around_[6 * b + 2 * a];
    const unsigned at = own != 0 ? (((own - 1) & axis) | rest) : (axis | rest);
    if (block == kNone || ((masks_[block] >> at) & 1U) == 0) return -1;
    const std::uint64_t before = masks_[block] & ((1ULL << at) - 1);
    return static_cast<std::int64_t>(first_[block]) + __builtin_popcountll(before);
  }

  static constexpr std::uint32_t kNone = 0xFFFFFFFFU;
  static std::size_t hash(std::uint64_t k) { return static_cast<std::size_t>((k * 0x9E3779B97F4A7C15ULL) >> 20); }
  [[nodiscard]] std::uint32_t block_of(std::uint64_t key) const {
    for (std::size_t i = hash(key) & mask_;; i = (i + 1) & mask_) {
      if (slots_[i] == kNone || keys_[slots_[i]] == key) return slots_[i];
    }
  }
  [[nodiscard]] std::uint64_t mask(std::uint32_t block) const noexcept { return block == kNone ? 0 : masks_[block]; }
  std::vector<std::uint64_t> keys_, masks_;
  std::vector<std::uint32_t> first_;   // the index of each block's first node
  std::vector<std::uint32_t> around_;  // each block's six face-neighbour blocks (kNone: empty)
  std::vector<std::uint32_t> slots_;
  std::size_t mask_ = 0;
};

/// The models of the occupancy bits: 8 child-level contexts x 64 neighbour contexts x
/// the 255 states of the bits before (a binary tree over the byte, rooted at 1).
class OccupancyModels {
 public:
  BitModel& at(unsigned lower, unsigned ctx, unsigned prefix) { return models_[((lower << 6 | ctx) << 8) | prefix]; }

 private:
  std::vector<BitModel> models_ = std::vector<BitModel>(8 * 64 * 256);
};

/// The occupancy models of §2.7.4: per bit, three context models, each a YoungBitModel,
/// mixed in the logistic domain with weights that learn per (child, siblings so far).
class MixedContexts {
 public:
  /// Starts a level: forgets the planes of the level before.
  void begin_level(int level) {
    const std::size_t size = std::size_t{1} << std::min(level, kPlaneBits);
    for (auto& axis : plane_key_) axis.assign(size, kNoKey);
    for (auto& axis : plane_) axis.assign(size, 2);
    plane_mask_ = size - 1;
  }
  /// Starts node (x, y, z) of the level, `faces` its six face neighbours (bit 2a below
  /// along axis a, 2a+1 above).
  void begin_node(std::uint32_t x, std::uint32_t y, std::uint32_t z, unsigned faces) {
    coord_[0] = x;
    coord_[1] = y;
    coord_[2] = z;
    faces_ = faces;
    for (int a = 0; a < 3; ++a) {
      const std::size_t at = coord_[a] & plane_mask_;
      predicted_[a] = plane_key_[a][at] == coord_[a] ? plane_[a][at] : 2U;
    }
  }
  /// The probability of a 0 (in 1/4096) of child i's bit; `so_far` the bits before it,
  /// `low` which of its lower neighbours on the child level are occupied (bit a: along a).
  std::uint32_t p0(unsigned i, unsigned so_far, unsigned low) {
    unsigned near = 0, far = 0, plane = 0;
    for (unsigned a = 0; a < 3; ++a) {
      const unsigned side = (i >> a) & 1U;  // 1: the child is in the upper half along a
      near |= ((faces_ >> (2 * a + side)) & 1U) << a;
      far |= ((faces_ >> (2 * a + (side ^ 1U))) & 1U) << a;
    }
    for (int a = 2; a >= 0; --a) {
      const unsigned p = predicted_[a];
      plane = 3 * plane + (p == 2U ? 0U : p == ((i >> a) & 1U) ? 1U : 2U);
    }
    const unsigned set = i * 8 + kOnes[so_far & 127U];
    const unsigned faces = (set * 8 + near) * 8 + low;
    index_[0] = faces;
    index_[1] = faces * 8 + far;
    index_[2] = (set * 27 + plane) * 8 + low;
    return mix_.p0(models_[0][index_[0]], models_[1][index_[1]], models_[2][index_[2]], set);
  }
  /// Learns child i's bit after p0.
  void update(bool bit) { mix_.learn(bit); }
  /// Ends the node, `byte` its children: its plane along each axis is remembered.
  void end_node(unsigned byte) {
    for (unsigned a = 0; a < 3; ++a) {
      unsigned lower = 0, upper = 0;
      for (unsigned i = 0; i < 8; ++i)
        if ((byte >> i) & 1U) ((i >> a) & 1U ? upper : lower) = 1;
      const std::size_t at = coord_[a] & plane_mask_;
      plane_key_[a][at] = coord_[a];
      plane_[a][at] = static_cast<std::uint8_t>(lower != 0 && upper != 0 ? 2 : upper);
    }
  }

 private:
  static constexpr int kPlaneBits = 14;
  /// The set bits of 0..127 (the siblings before a child).
  static constexpr std::array<std::uint8_t, 128> kOnes = [] {
    std::array<std::uint8_t, 128> t{};
    for (unsigned v = 0; v < 128; ++v) t[v] = static_cast<std::uint8_t>((v & 1U) + ((v >> 1) & 1U) + ((v >> 2) & 1U) + ((v >> 3) & 1U) +
                                                                        ((v >> 4) & 1U) + ((v >> 5) & 1U) + ((v >> 6) & 1U));
    return t;
  }();
  static constexpr std::uint32_t kNoKey = 0xFFFFFFFFU;
  std::array<std::vector<YoungBitModel>, 3> models_{std::vector<YoungBitModel>(4096),
                                                    std::vector<YoungBitModel>(4096 * 8),
                                                    std::vector<YoungBitModel>(64 * 27 * 8)};
  Mix3 mix_{64, 21845};  // weights 1/3 each, per (child, siblings so far)
  std::array<std::vector<std::uint32_t>, 3> plane_key_;
  std::array<std::vector<std::uint8_t>, 3> plane_;
  std::size_t plane_mask_ = 0;
  std::uint32_t coord_[3] = {0, 0, 0};
  unsigned faces_ = 0;
  unsigned predicted_[3] = {2, 2, 2};
  std::size_t index_[3] = {0, 0, 0};
};

/// Which of child i's three lower neighbours on the child level are occupied (bit a: along
/// axis a), all known to the decoder: a sibling coded before it (in `so_far`, bit j for
/// child j) or a child of the node's lower neighbour along a (whose occupancy byte is
/// `low[a]`, 0 when there is none), which comes earlier in Morton order.
unsigned lower_children(unsigned i, unsigned so_far, const unsigned low[3]) {
  unsigned out = 0;
  for (unsigned a = 0; a < 3; ++a) {
    const unsigned along = 1U << a;
    out |= (((i & along) != 0 ? so_far >> (i ^ along) : low[a] >> (i | along)) & 1U) << a;
  }
  return out;
}

/// The nodes of every level of the octree over `leaves`: [0] the root, [depth] the leaves.
std::vector<std::vector<std::uint64_t>> levels_of(const std::vector<std::uint64_t>& leaves, int depth) {
  std::vector<std::vector<std::uint64_t>> levels(static_cast<std::size_t>(depth) + 1);
  levels[static_cast<std::size_t>(depth)] = leaves;
  for (int l = depth - 1; l >= 0; --l) {
    const auto& below = levels[static_cast<std::size_t>(l) + 1];
    auto& here = levels[static_cast<std::size_t>(l)];
    here.reserve(below.size() / 2 + 1);
    for (const std::uint64_t n : below)
      if (here.empty() || here.back() != (n >> 3)) here.push_back(n >> 3);
  }
  return levels;
}

}  // namespace

std::uint64_t morton(std::uint32_t x, std::uint32_t y, std::uint32_t z) {
  return spread(x) | (spread(y) << 1) | (spread(z) << 2);
}

void unmorton(std::uint64_t code, std::uint32_t& x, std::uint32_t& y, std::uint32_t& z) {
  x = compact(code);
  y = compact(code >> 1);
  z = compact(code >> 2);
}

bool encode_occupancy(RangeEncoder& enc, const std::vector<std::uint64_t>& leaves, int depth,
                      OccupancyContexts contexts, std::size_t give_up_bytes) {
  const auto levels = levels_of(leaves, depth);
  const bool mixed = contexts == OccupancyContexts::kMixed;
  std::unique_ptr<OccupancyModels> models = mixed ? nullptr : std::make_unique<OccupancyModels>();
  std::unique_ptr<MixedContexts> mix = mixed ? std::make_unique<MixedContexts>() : nullptr;
  LevelOccupancy occupied;
  std::vector<std::uint8_t> bytes;
  for (int l = 0; l < depth; ++l) {
    const auto& nodes = levels[static_cast<std::size_t>(l)];
    const auto& children = levels[static_cast<std::size_t>(l) + 1];
    occupied.assign(nodes);
    if (mixed) mix->begin_level(l);
    bytes.assign(nodes.size(), 0);
    // (children and nodes are both in Morton order: one walk)
    std::size_t j = 0;
    for (std::size_t k = 0; k < nodes.size(); ++k)
      for (; j < children.size() && (children[j] >> 3) == nodes[k]; ++j) bytes[k] |= static_cast<std::uint8_t>(1U << (children[j] & 7U));
    std::size_t b = 0;
    for (std::size_t k = 0; k < nodes.size(); ++k) {
      if ((k & 255U) == 0 && enc.bytes_out() > give_up_bytes) return false;
      const std::uint64_t n = nodes[k];
      const unsigned byte = bytes[k];
      while (occupied.key(b) != (n >> 6)) ++b;
      const unsigned ctx = occupied.neighbours(b, n);
      unsigned low[3];
      occupied.lower_bytes(b, n, bytes, low);
      if (mixed) {
        std::uint32_t x = 0, y = 0, z = 0;
        unmorton(n, x, y, z);
        mix->begin_node(x, y, z, ctx);
      }
      unsigned prefix = 1;
      for (unsigned i = 0; i < 8; ++i) {
        const unsigned bit = (byte >> i) & 1U;
        // An occupied node has a child: after seven empty ones, the eighth is not coded.
        if (!(i == 7 && prefix == 1)) {
          const unsigned so_far = byte & ((1U << i) - 1);
          if (mixed) {
            enc.put(mix->p0(i, so_far, lower_children(i, so_far, low)), bit != 0);
            mix->update(bit != 0);
          } else {
            enc.put(models->at(lower_children(i, so_far, low), ctx, prefix), bit != 0);
          }
        }
        prefix = 2 * prefix + bit;
      }
      if (mixed) mix->end_node(byte);
    }
  }
  return true;
}

bool decode_occupancy(RangeDecoder& dec, int depth, std::uint64_t max_leaves, std::vector<std::uint64_t>& leaves,
                      OccupancyContexts contexts) {
  const bool mixed = contexts == OccupancyContexts::kMixed;
  std::unique_ptr<OccupancyModels> models = mixed ? nullptr : std::make_unique<OccupancyModels>();
  std::unique_ptr<MixedContexts> mix = mixed ? std::make_unique<MixedContexts>() : nullptr;
  LevelOccupancy occupied;
  std::vector<std::uint64_t> nodes = {0}, children;
  std::vector<std::uint8_t> bytes;
  for (int l = 0; l < depth; ++l) {
    occupied.assign(nodes);
    if (mixed) mix->begin_level(l);
    children.clear();
    bytes.clear();
    std::size_t b = 0;
    for (const std::uint64_t n : nodes) {
      while (occupied.key(b) != (n >> 6)) ++b;
      const unsigned ctx = occupied.neighbours(b, n);
      unsigned low[3];
      occupied.lower_bytes(b, n, bytes, low);
      if (mixed) {
        std::uint32_t x = 0, y = 0, z = 0;
        unmorton(n, x, y, z);
        mix->begin_node(x, y, z, ctx);
      }
      unsigned prefix = 1, byte = 0;
      for (unsigned i = 0; i < 8; ++i) {
        bool bit = true;
        if (!(i == 7 && prefix == 1)) {
          if (mixed) {
            bit = dec.get(mix->p0(i, byte, lower_children(i, byte, low)));
            mix->update(bit);
          } else {
            bit = dec.get(models->at(lower_children(i, byte, low), ctx, prefix));
          }
        }
        prefix = 2 * prefix + (bit ? 1U : 0U);
        if (bit) {
          byte |= 1U << i;
          children.push_back(n * 8 + i);
        }
      }
      if (mixed) mix->end_node(byte);
      bytes.push_back(static_cast<std::uint8_t>(byte));
      if (children.size() > max_leaves) return false;
    }
    nodes.swap(children);
  }
  leaves = std::move(nodes);
  return true;
}

}  // namespace lex3d::residual::detail
