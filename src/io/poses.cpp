// Pose and number lists (KITTI poses.txt / times.txt) and 3DTK `.pose` files.

#include <cmath>
#include <string>
#include <vector>

#include <Eigen/SVD>

#include "io/internal.hpp"
#include "lex3d/io/io.hpp"

namespace lex3d::io {

using detail::line_prefix;
using detail::msg;
using detail::not_a_number;

namespace {

constexpr std::uint64_t kMaxListBytes = 1ULL << 30;

/// Parses the numbers of one line into `out`; on a token that is not a number
/// returns false with `bad` set to it.
bool parse_line_numbers(std::string_view line, std::vector<double>& out, std::string_view& bad) {
  out.clear();
  bool ok = true;
  detail::for_each_token(line, false, [&](const char* b, const char* e) {
    double v = 0.0;
    if (!detail::parse_number(b, e, v)) {
      bad = std::string_view(b, static_cast<std::size_t>(e - b));
      ok = false;
      return false;
    }
    out.push_back(v);
    return out.size() <= 64;  // enough to report "too many"
  });
  return ok;
}

/// Reads the list file `path` (at most kMaxListBytes; empty is an error) and
/// calls `fn(lines, line)` on each of its lines, stopping at the first error.
template <typename Fn>
Status for_each_list_line(const std::string& path, Fn&& fn) {
  auto file = read_file(path, kMaxListBytes);
  if (!file.ok()) return file.status();
  const auto& bytes = file.value();
  if (bytes.empty()) return bad_data(msg(path, "file is empty"), 0);
  const char* text = reinterpret_cast<const char*>(bytes.data());
  detail::LineCursor lines(text, text + bytes.size());
  std::string_view line;
  while (lines.next(line)) {
    if (Status s = fn(lines, line); !s.ok()) return s;
  }
  return {};
}

/// Nearest rotation to `m` (SVD), or false when `m` is not a rotation within `tol`.
bool orthonormalise(const Eigen::Matrix3d& m, double tol, Eigen::Matrix3d& out, double& err) {
  err = (m.transpose() * m - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (!std::isfinite(err) || err > tol || m.determinant() <= 0.0) return false;
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(m, Eigen::ComputeFullU | Eigen::ComputeFullV);
  out = svd.matrixU() * svd.matrixV().transpose();
  if (out.determinant() < 0.0) return false;
  return true;
}

}  // namespace

StatusOr<std::vector<Pose>> read_pose_list(const std::string& path) {
  std::vector<double> v;
  std::vector<Pose> poses;
  Status s = for_each_list_line(path, [&](const detail::LineCursor& lines, std::string_view line) -> Status {
    const std::uint64_t n = lines.line_no();
    if (detail::trim(line).empty()) {
      return bad_data(msg(path, line_prefix(n) + "blank line (one pose a line, 12 numbers)"),
                      lines.line_offset());
    }
    std::string_view bad;
    if (!parse_line_numbers(line, v, bad)) {
      return bad_data(msg(path, not_a_number(n, bad)), lines.line_offset());
    }
    if (v.size() != 12) {
      return bad_data(msg(path, line_prefix(n) + "expected 12 numbers (3x4 matrix [R | t]), found " +
                                    (v.size() > 64 ? std::string("more than 64") : std::to_string(v.size()))),
                      lines.line_offset());
    }
    Eigen::Matrix3d m;
    Eigen::Vector3d t;
    bool finite = true;
    for (int row = 0; row < 3; ++row) {
      for (int col = 0; col < 3; ++col) m(row, col) = v[static_cast<std::size_t>(row * 4 + col)];
      t(row) = v[static_cast<std::size_t>(row * 4 + 3)];
    }
    for (double x : v) finite = finite && std::isfinite(x);
    if (!finite) {
      return bad_data(msg(path, line_prefix(n) + "pose has a NaN or Inf entry"), lines.line_offset());
    }
    Eigen::Matrix3d R;
    double err = 0.0;
    if (!orthonormalise(m, 1e-3, R, err)) {
      return bad_data(msg(path, line_prefix(n) + "not a rotation (|R^T R - I| = " + std::to_string(err) +
                                    ", det = " + std::to_string(m.determinant()) + ")"),
                      lines.line_offset());
    }
    Pose p = Pose::Identity();
    p.linear() = R;
    p.translation() = t;
    poses.push_back(p);
    return {};
  });
  if (!s.ok()) return s;
  return poses;
}

StatusOr<std::vector<double>> read_number_list(const std::string& path) {
  std::vector<double> v;
  std::vector<double> out;
  Status s = for_each_list_line(path, [&](const detail::LineCursor& lines, std::string_view line) -> Status {
    const std::string_view t = detail::trim(line);
    if (t.empty() || t.front() == '#') return {};  // blank and comment lines are skipped
    std::string_view bad;
    if (!parse_line_numbers(t, v, bad)) {
      return bad_data(msg(path, not_a_number(lines.line_no(), bad)), lines.line_offset());
    }
    if (v.size() != 1) {
      return bad_data(msg(path, line_prefix(lines.line_no()) + "expected one number, found " +
                                    std::to_string(v.size())),
                      lines.line_offset());
    }
    out.push_back(v[0]);
    return {};
  });
  if (!s.ok()) return s;
  return out;
}

namespace detail {

// A 3DTK `.pose` file: line 1 `tx ty tz` (cm), line 2 `rx ry rz` (degrees), both
// in the left-handed 3DTK frame. 3DTK builds the rotation as
// R = Rx(rx) * Ry(ry) * Rz(rz) (EulerToMatrix4), applied as p_world = R p + t.
// With M the axis map of uos_to_lex3d (x' = z, y' = -x, z' = y; det M = -1),
// the same motion in lex3d's right-handed metric frame is
//   R' = M R M^T (a proper rotation again),   t' = M t / 100.
StatusOr<Pose> read_uos_pose(const std::string& pose_path) {
  auto file = read_file(pose_path, 1U << 20);
  if (!file.ok()) return file.status();
  const auto& bytes = file.value();
  if (bytes.empty()) return bad_data(msg(pose_path, "pose file is empty"), 0);
  const char* text = reinterpret_cast<const char*>(bytes.data());
  LineCursor lines(text, text + bytes.size());
  std::string_view line;
  std::vector<double> vals;
  std::vector<double> v;
  int rows = 0;
  while (rows < 2 && lines.next(line)) {
    const std::string_view t = trim(line);
    if (t.empty() || t.front() == '#') continue;
    std::string_view bad;
    if (!parse_line_numbers(t, v, bad)) {
      return bad_data(msg(pose_path, not_a_number(lines.line_no(), bad)), lines.line_offset());
    }
    if (v.size() != 3) {
      return bad_data(msg(pose_path, line_prefix(lines.line_no()) + "expected 3 numbers (" +
                                         (rows == 0 ? "tx ty tz cm" : "rx ry rz degrees") + "), found " +
                                         std::to_string(v.size())),
                      lines.line_offset());
    }
    for (double x : v) {
      if (!std::isfinite(x)) {
        return bad_data(msg(pose_path, line_prefix(lines.line_no()) + "NaN or Inf value"),
                        lines.line_offset());
      }
    }
    vals.insert(vals.end(), v.begin(), v.end());
    ++rows;
  }
  if (rows < 2) {
    return bad_data(msg(pose_path, "expected two lines (tx ty tz / rx ry rz), found " + std::to_string(rows)));
  }
  constexpr double kDeg = 3.14159265358979323846 / 180.0;
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(vals[3] * kDeg, Eigen::Vector3d::UnitX()) *
                             Eigen::AngleAxisd(vals[4] * kDeg, Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(vals[5] * kDeg, Eigen::Vector3d::UnitZ()))
                                .toRotationMatrix();
  Eigen::Matrix3d M;
  M << 0, 0, 1,   //
      -1, 0, 0,   //
      0, 1, 0;
  Pose p = Pose::Identity();
  p.linear() = M * R * M.transpose();
  p.translation() = uos_to_lex3d(vals[0], vals[1], vals[2]);
  return p;
}

}  // namespace detail

}  // namespace lex3d::io
