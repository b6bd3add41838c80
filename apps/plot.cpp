#include "plot.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>

namespace lex3d::plot {

namespace {

// The font: one glyph a character, 9 rows of 5 columns ('#' drawn); rows 0-6 stand on the
// baseline, rows 7-8 hang below it. Rows not given are empty.
struct Glyph {
  char c;
  const char* rows[9];
};

// clang-format off
const Glyph kFont[] = {
  {' ', {}},
  {'0', {".###.", "#...#", "#..##", "#.#.#", "##..#", "#...#", ".###."}},
  {'1', {"..#..", ".##..", "..#..", "..#..", "..#..", "..#..", ".###."}},
  {'2', {".###.", "#...#", "....#", "...#.", "..#..", ".#...", "#####"}},
  {'3', {"#####", "...#.", "..#..", "...#.", "....#", "#...#", ".###."}},
  {'4', {"...#.", "..##.", ".#.#.", "#..#.", "#####", "...#.", "...#."}},
  {'5', {"#####", "#....", "####.", "....#", "....#", "#...#", ".###."}},
  {'6', {"..##.", ".#...", "#....", "####.", "#...#", "#...#", ".###."}},
  {'7', {"#####", "....#", "...#.", "..#..", ".#...", ".#...", ".#..."}},
  {'8', {".###.", "#...#", "#...#", ".###.", "#...#", "#...#", ".###."}},
  {'9', {".###.", "#...#", "#...#", ".####", "....#", "...#.", ".##.."}},
  {'A', {".###.", "#...#", "#...#", "#####", "#...#", "#...#", "#...#"}},
  {'B', {"####.", "#...#", "#...#", "####.", "#...#", "#...#", "####."}},
  {'C', {".###.", "#...#", "#....", "#....", "#....", "#...#", ".###."}},
  {'D', {"###..", "#..#.", "#...#", "#...#", "#...#", "#..#.", "###.."}},
  {'E', {"#####", "#....", "#....", "####.", "#....", "#....", "#####"}},
  {'F', {"#####", "#....", "#....", "####.", "#....", "#....", "#...."}},
  {'G', {".###.", "#...#", "#....", "#.###", "#...#", "#...#", ".####"}},
  {'H', {"#...#", "#...#", "#...#", "#####", "#...#", "#...#", "#...#"}},
  {'I', {".###.", "..#..", "..#..", "..#..", "..#..", "..#..", ".###."}},
  {'J', {"..###", "...#.", "...#.", "...#.", "...#.", "#..#.", ".##.."}},
  {'K', {"#...#", "#..#.", "#.#..", "##...", "#.#..", "#..#.", "#...#"}},
  {'L', {"#....", "#....", "#....", "#....", "#....", "#....", "#####"}},
  {'M', {"#...#", "##.##", "#.#.#", "#.#.#", "#...#", "#...#", "#...#"}},
  {'N', {"#...#", "#...#", "##..#", "#.#.#", "#..##", "#...#", "#...#"}},
  {'O', {".###.", "#...#", "#...#", "#...#", "#...#", "#...#", ".###."}},
  {'P', {"####.", "#...#", "#...#", "####.", "#....", "#....", "#...."}},
  {'Q', {".###.", "#...#", "#...#", "#...#", "#.#.#", "#..#.", ".##.#"}},
  {'R', {"####.", "#...#", "#...#", "####.", "#.#..", "#..#.", "#...#"}},
  {'S', {".####", "#....", "#....", ".###.", "....#", "....#", "####."}},
  {'T', {"#####", "..#..", "..#..", "..#..", "..#..", "..#..", "..#.."}},
  {'U', {"#...#", "#...#", "#...#", "#...#", "#...#", "#...#", ".###."}},
  {'V', {"#...#", "#...#", "#...#", "#...#", "#...#", ".#.#.", "..#.."}},
  {'W', {"#...#", "#...#", "#...#", "#.#.#", "#.#.#", "#.#.#", ".#.#."}},
  {'X', {"#...#", "#...#", ".#.#.", "..#..", ".#.#.", "#...#", "#...#"}},
  {'Y', {"#...#", "#...#", ".#.#.", "..#..", "..#..", "..#..", "..#.."}},
  {'Z', {"#####", "....#", "...#.", "..#..", ".#...", "#....", "#####"}},
  {'a', {".....", ".....", ".###.", "....#", ".####", "#...#", ".####"}},
  {'b', {"#....", "#....", "####.", "#...#", "#...#", "#...#", "####."}},
  {'c', {".....", ".....", ".###.", "#....", "#....", "#...#", ".###."}},
  {'d', {"....#", "....#", ".####", "#...#", "#...#", "#...#", ".####"}},
  {'e', {".....", ".....", ".###.", "#...#", "#####", "#....", ".###."}},
  {'f', {"..##.", ".#..#", ".#...", "###..", ".#...", ".#...", ".#..."}},
  {'g', {".....", ".....", ".####", "#...#", "#...#", "#...#", ".####", "....#", ".###."}},
  {'h', {"#....", "#....", "#.##.", "##..#", "#...#", "#...#", "#...#"}},
  {'i', {"..#..", ".....", ".##..", "..#..", "..#..", "..#..", ".###."}},
  {'j', {"...#.", ".....", "..##.", "...#.", "...#.", "...#.", "...#.", "#..#.", ".##.."}},
  {'k', {"#....", "#....", "#..#.", "#.#..", "##...", "#.#..", "#..#."}},
  {'l', {".##..", "..#..", "..#..", "..#..", "..#..", "..#..", ".###."}},
  {'m', {".....", ".....", "##.#.", "#.#.#", "#.#.#", "#.#.#", "#.#.#"}},
  {'n', {".....", ".....", "#.##.", "##..#", "#...#", "#...#", "#...#"}},
  {'o', {".....", ".....", ".###.", "#...#", "#...#", "#...#", ".###."}},
  {'p', {".....", ".....", "####.", "#...#", "#...#", "#...#", "####.", "#....", "#...."}},
  {'q', {".....", ".....", ".####", "#...#", "#...#", "#...#", ".####", "....#", "....#"}},
  {'r', {".....", ".....", "#.##.", "##..#", "#....", "#....", "#...."}},
  {'s', {".....", ".....", ".####", "#....", ".###.", "....#", "####."}},
  {'t', {".#...", ".#...", "###..", ".#...", ".#...", ".#..#", "..##."}},
  {'u', {".....", ".....", "#...#", "#...#", "#...#", "#..##", ".##.#"}},
  {'v', {".....", ".....", "#...#", "#...#", "#...#", ".#.#.", "..#.."}},
  {'w', {".....", ".....", "#...#", "#...#", "#.#.#", "#.#.#", ".#.#."}},
  {'x', {".....", ".....", "#...#", ".#.#.", "..#..", ".#.#.", "#...#"}},
  {'y', {".....", ".....", "#...#", "#...#", "#...#", "#...#", ".####", "....#", ".###."}},
  {'z', {".....", ".....", "#####", "...#.", "..#..", ".#...", "#####"}},
  {'.', {".....", ".....", ".....", ".....", ".....", ".##..", ".##.."}},
  {',', {".....", ".....", ".....", ".....", ".....", ".##..", ".##..", "..#..", ".#..."}},
  {'-', {".....", ".....", ".....", ".###."}},
  {'+', {".....", "..#..", "..#..", "#####", "..#..", "..#.."}},
  {'%', {"##...", "##..#", "...#.", "..#..", ".#...", "#..##", "...##"}},
  {'(', {"...#.", "..#..", ".#...", ".#...", ".#...", "..#..", "...#."}},
  {')', {".#...", "..#..", "...#.", "...#.", "...#.", "..#..", ".#..."}},
  {'[', {".###.", ".#...", ".#...", ".#...", ".#...", ".#...", ".###."}},
  {']', {".###.", "...#.", "...#.", "...#.", "...#.", "...#.", ".###."}},
  {'/', {".....", "....#", "...#.", "..#..", ".#...", "#...."}},
  {':', {".....", ".##..", ".##..", ".....", ".##..", ".##.."}},
  {';', {".....", ".##..", ".##..", ".....", ".##..", ".##..", "..#..", ".#..."}},
  {'=', {".....", ".....", "#####", ".....", "#####"}},
  {'<', {"...#.", "..#..", ".#...", "#....", ".#...", "..#..", "...#."}},
  {'>', {".#...", "..#..", "...#.", "....#", "...#.", "..#..", ".#..."}},
  {'_', {".....", ".....", ".....", ".....", ".....", ".....", ".....", "#####"}},
  {'\'', {"..#..", "..#..", ".#..."}},
  {'"', {".#.#.", ".#.#.", ".#.#."}},
  {'!', {"..#..", "..#..", "..#..", "..#..", "..#..", ".....", "..#.."}},
  {'?', {".###.", "#...#", "....#", "...#.", "..#..", ".....", "..#.."}},
  {'*', {".....", "..#..", "#.#.#", ".###.", "#.#.#", "..#.."}},
  {'#', {".#.#.", ".#.#.", "#####", ".#.#.", "#####", ".#.#.", ".#.#."}},
  {'&', {".##..", "#..#.", "#.#..", ".#...", "#.#.#", "#..#.", ".##.#"}},
  {'|', {"..#..", "..#..", "..#..", "..#..", "..#..", "..#..", "..#..", "..#.."}},
  {'~', {".....", ".....", ".#...", "#.#.#", "...#."}},
  {'@', {".###.", "#...#", "#.###", "#.#.#", "#.##.", "#....", ".####"}},
};
// Any other byte: an empty box.
const Glyph kUnknown = {'\0', {"#####", "#...#", "#...#", "#...#", "#...#", "#...#", "#####"}};
// clang-format on

const Glyph& glyph(char ch) {
  static const std::array<const Glyph*, 256> table = [] {
    std::array<const Glyph*, 256> t{};
    t.fill(&kUnknown);
    for (const Glyph& g : kFont) t[static_cast<unsigned char>(g.c)] = &g;
    return t;
  }();
  return *table[static_cast<unsigned char>(ch)];
}

// Offset of a box of this size so that its anchor is at 0.
int anchor(int size, Align a) {
  switch (a) {
    case Align::kStart: return 0;
    case Align::kCentre: return -size / 2;
    case Align::kEnd: return -size;
  }
  return 0;
}

}  // namespace

int text_width(const std::string& s, int scale) {
  if (s.empty()) return 0;
  return (static_cast<int>(s.size()) * kGlyphAdvance - 1) * scale;
}

Canvas::Canvas(int width, int height, Rgb background)
    : width_(std::max(width, 1)), height_(std::max(height, 1)),
      rgb_(static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_) * 3) {
  for (std::size_t k = 0; k < rgb_.size(); k += 3) {
    rgb_[k] = background.r;
    rgb_[k + 1] = background.g;
    rgb_[k + 2] = background.b;
  }
}

Rgb Canvas::pixel(int x, int y) const {
  if (x < 0 || y < 0 || x >= width_ || y >= height_) return {};
  const std::size_t k = 3 * (static_cast<std::size_t>(y) * static_cast<std::size_t>(width_) + static_cast<std::size_t>(x));
  return {rgb_[k], rgb_[k + 1], rgb_[k + 2]};
}

void Canvas::set(int x, int y, Rgb c) {
  if (x < 0 || y < 0 || x >= width_ || y >= height_) return;
  const std::size_t k = 3 * (static_cast<std::size_t>(y) * static_cast<std::size_t>(width_) + static_cast<std::size_t>(x));
  rgb_[k] = c.r;
  rgb_[k + 1] = c.g;
  rgb_[k + 2] = c.b;
}

void Canvas::fill(const Rect& r, Rgb c) {
  const int x0 = std::max(r.left, 0), x1 = std::min(r.right, width_);
  const int y0 = std::max(r.top, 0), y1 = std::min(r.bottom, height_);
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x) set(x, y, c);
}

void Canvas::frame(const Rect& r, Rgb c, int thickness) {
  for (int t = 0; t < thickness; ++t) {
    fill({r.left + t, r.top + t, r.right - t, r.top + t + 1}, c);
    fill({r.left + t, r.bottom - t - 1, r.right - t, r.bottom - t}, c);
    fill({r.left + t, r.top + t, r.left + t + 1, r.bottom - t}, c);
    fill({r.right - t - 1, r.top + t, r.right - t, r.bottom - t}, c);
  }
}

void Canvas::line(double x0, double y0, double x1, double y1, Rgb c, int thickness) {
  if (!std::isfinite(x0) || !std::isfinite(y0) || !std::isfinite(x1) || !std::isfinite(y1)) return;
  // Far outside the canvas: nothing to draw (and no loop of billions of steps).
  const double lim = 4.0 * (width_ + height_);
  if (std::abs(x0) > lim || std::abs(x1) > lim || std::abs(y0) > lim || std::abs(y1) > lim) return;
  const int n = static_cast<int>(std::ceil(std::max(std::abs(x1 - x0), std::abs(y1 - y0)))) + 1;
  const int lo = -(thickness - 1) / 2, hi = thickness / 2;
  for (int i = 0; i <= n; ++i) {
    const double t = static_cast<double>(i) / n;
    const int x = static_cast<int>(std::lround(x0 + (x1 - x0) * t));
    const int y = static_cast<int>(std::lround(y0 + (y1 - y0) * t));
    for (int dy = lo; dy <= hi; ++dy)
      for (int dx = lo; dx <= hi; ++dx) set(x + dx, y + dy, c);
  }
}

void Canvas::marker(int x, int y, Marker m, int size, Rgb c) {
  const int r = std::max(size / 2, 1);
  switch (m) {
    case Marker::kSquare: fill({x - r, y - r, x + r + 1, y + r + 1}, c); break;
    case Marker::kCircle:
      for (int dy = -r; dy <= r; ++dy)
        for (int dx = -r; dx <= r; ++dx)
          if (dx * dx + dy * dy <= r * r + r) set(x + dx, y + dy, c);
      break;
    case Marker::kDiamond:
      for (int dy = -r; dy <= r; ++dy)
        for (int dx = -r; dx <= r; ++dx)
          if (std::abs(dx) + std::abs(dy) <= r) set(x + dx, y + dy, c);
      break;
    case Marker::kCross:
      for (int d = -r; d <= r; ++d) {
        for (int w = 0; w <= 1; ++w) {
          set(x + d + w, y + d, c);
          set(x + d + w, y - d, c);
        }
      }
      break;
    case Marker::kPlus:
      for (int d = -r; d <= r; ++d)
        for (int w = 0; w <= 1; ++w) {
          set(x + d, y + w, c);
          set(x + w, y + d, c);
        }
      break;
  }
}

Rect Canvas::text(int x, int y, const std::string& s, Rgb c, int scale, Align h, Align v) {
  scale = std::max(scale, 1);
  const int w = text_width(s, scale), ch = kCapHeight * scale;
  const int x0 = x + anchor(w, h), y0 = y + anchor(ch, v);
  for (std::size_t i = 0; i < s.size(); ++i) {
    const Glyph& g = glyph(s[i]);
    const int gx = x0 + static_cast<int>(i) * kGlyphAdvance * scale;
    for (int row = 0; row < 9; ++row) {
      const char* bits = g.rows[row];
      if (bits == nullptr) break;
      for (int col = 0; col < 5 && bits[col] != '\0'; ++col)
        if (bits[col] == '#') fill({gx + col * scale, y0 + row * scale, gx + (col + 1) * scale, y0 + (row + 1) * scale}, c);
    }
  }
  return {x0, y0, x0 + w, y0 + ch};
}

Rect Canvas::text_up(int x, int y, const std::string& s, Rgb c, int scale, Align h, Align v) {
  scale = std::max(scale, 1);
  const int len = text_width(s, scale), ch = kCapHeight * scale;
  // Along the text is upwards: its start is at the bottom.
  const int bottom = y - anchor(len, h);  // one past the first pixel row
  const int left = x + anchor(ch, v);     // the glyphs' tops are on the left
  for (std::size_t i = 0; i < s.size(); ++i) {
    const Glyph& g = glyph(s[i]);
    const int along0 = static_cast<int>(i) * kGlyphAdvance * scale;
    for (int row = 0; row < 9; ++row) {
      const char* bits = g.rows[row];
      if (bits == nullptr) break;
      for (int col = 0; col < 5 && bits[col] != '\0'; ++col)
        if (bits[col] == '#') {
          const int px = left + row * scale;
          const int py = bottom - along0 - (col + 1) * scale;
          fill({px, py, px + scale, py + scale}, c);
        }
    }
  }
  return {left, bottom - len, left + ch, bottom};
}

Ticks nice_ticks(double lo, double hi, int max_ticks, double min_step) {
  Ticks t;
  if (!std::isfinite(lo) || !std::isfinite(hi)) return t;
  if (hi < lo) std::swap(lo, hi);
  max_ticks = std::max(max_ticks, 2);
  const double span = hi - lo;
  double step = span > 0 ? span / (max_ticks - 1) : 1.0;
  const double p = std::pow(10.0, std::floor(std::log10(step)));
  double nice = 10.0 * p;
  for (const double m : {1.0, 2.0, 5.0, 10.0})
    if (m * p >= step * (1 - 1e-9)) {
      nice = m * p;
      break;
    }
  nice = std::max(nice, min_step);
  // Enough fewer ticks when the rounding still leaves too many.
  while (std::floor(hi / nice + 1e-9) - std::ceil(lo / nice - 1e-9) + 1 > max_ticks) nice *= 2;
  t.step = nice;
  t.decimals = std::max(0, static_cast<int>(std::ceil(-std::log10(nice) - 1e-9)));
  if (std::abs(nice * std::pow(10.0, t.decimals) - std::round(nice * std::pow(10.0, t.decimals))) > 1e-6) ++t.decimals;
  const long first = static_cast<long>(std::ceil(lo / nice - 1e-9));
  const long last = static_cast<long>(std::floor(hi / nice + 1e-9));
  for (long k = first; k <= last && t.values.size() < 1000; ++k) t.values.push_back(static_cast<double>(k) * nice);
  return t;
}

std::string format_tick(double v, int decimals) {
  char buf[64];
  const double r = std::abs(v) < 0.5 * std::pow(10.0, -decimals) ? 0.0 : v;  // no "-0"
  std::snprintf(buf, sizeof buf, "%.*f", std::clamp(decimals, 0, 12), r);
  return buf;
}

Chart::Chart(Canvas& canvas, Rect area, double x0, double x1, double y0, double y1, bool y_down)
    : c_(canvas), area_(area), x0_(x0), x1_(x1), y0_(y0), y1_(y1), y_down_(y_down) {}

double Chart::px(double x) const {
  const double span = x1_ - x0_;
  return area_.left + (span != 0 ? (x - x0_) / span : 0.5) * (area_.width() - 1);
}

double Chart::py(double y) const {
  const double span = y1_ - y0_;
  const double t = span != 0 ? (y - y0_) / span : 0.5;
  return y_down_ ? area_.top + t * (area_.height() - 1) : area_.bottom - 1 - t * (area_.height() - 1);
}

void Chart::axes(const Ticks& xt, const Ticks& yt, const std::string& xlabel, const std::string& ylabel, bool grid,
                 int scale) {
  const int tick = 5, gap = 3;
  if (grid) {
    for (const double v : xt.values) {
      const int x = static_cast<int>(std::lround(px(v)));
      if (x > area_.left && x < area_.right - 1) c_.fill({x, area_.top + 1, x + 1, area_.bottom - 1}, kLightGrey);
    }
    for (const double v : yt.values) {
      const int y = static_cast<int>(std::lround(py(v)));
      if (y > area_.top && y < area_.bottom - 1) c_.fill({area_.left + 1, y, area_.right - 1, y + 1}, kLightGrey);
    }
  }
  c_.frame(area_, kBlack);
  // Labels in pixel order (an axis may run either way); one that would touch the previous
  // label is left out.
  auto in_order = [](std::vector<std::pair<int, double>> v) {
    std::sort(v.begin(), v.end());
    return v;
  };
  std::vector<std::pair<int, double>> xs, ys;
  for (const double v : xt.values) xs.emplace_back(static_cast<int>(std::lround(px(v))), v);
  for (const double v : yt.values) ys.emplace_back(static_cast<int>(std::lround(py(v))), v);
  int last_right = -1000000;
  for (const auto& [x, v] : in_order(xs)) {
    c_.fill({x, area_.bottom, x + 1, area_.bottom + tick}, kBlack);
    const std::string s = format_tick(v, xt.decimals);
    const int w = text_width(s, scale);
    if (x - w / 2 <= last_right + 2 * kGlyphAdvance * scale) continue;
    last_right = c_.text(x, area_.bottom + tick + gap, s, kBlack, scale, Align::kCentre, Align::kStart).right;
  }
  int widest = 0, last_bottom = -1000000;
  for (const auto& [y, v] : in_order(ys)) {
    c_.fill({area_.left - tick, y, area_.left, y + 1}, kBlack);
    const int h = kCapHeight * scale;
    if (y - h / 2 < last_bottom + (kLineHeight - kCapHeight) * scale) continue;
    const Rect r = c_.text(area_.left - tick - gap, y, format_tick(v, yt.decimals), kBlack, scale, Align::kEnd, Align::kCentre);
    last_bottom = r.bottom;
    widest = std::max(widest, r.width());
  }
  if (!xlabel.empty())
    c_.text((area_.left + area_.right) / 2, area_.bottom + tick + gap + (kCapHeight + 6) * scale, xlabel, kBlack, scale,
            Align::kCentre, Align::kStart);
  if (!ylabel.empty())
    c_.text_up(area_.left - tick - gap - widest - 8 * scale, (area_.top + area_.bottom) / 2, ylabel, kBlack, scale,
               Align::kCentre, Align::kEnd);
}

void Chart::polyline(const std::vector<double>& xs, const std::vector<double>& ys, Rgb c, int thickness) {
  for (std::size_t i = 1; i < xs.size() && i < ys.size(); ++i) c_.line(px(xs[i - 1]), py(ys[i - 1]), px(xs[i]), py(ys[i]), c, thickness);
}

void title(Canvas& c, const Rect& area, int y, const std::string& s) {
  const int scale = text_width(s, 2) <= c.width() - 8 ? 2 : 1;
  int x = (area.left + area.right) / 2;
  const int w = text_width(s, scale);
  x = std::clamp(x, w / 2 + 4, std::max(w / 2 + 4, c.width() - w / 2 - 4));
  c.text(x, y, s, kBlack, scale, Align::kCentre, Align::kStart);
}

namespace {
constexpr int kLegendPad = 6, kLegendKey = 22;
}

Rect legend_size(const std::vector<LegendEntry>& entries, int scale) {
  int w = 0;
  for (const auto& e : entries) w = std::max(w, text_width(e.label, scale));
  const int h = static_cast<int>(entries.size()) * kLineHeight * scale + kLegendPad * 2 - (kLineHeight - kCapHeight) * scale;
  return {0, 0, w + kLegendKey * scale + kLegendPad * 3, h};
}

Rect legend(Canvas& c, int x, int y, const std::vector<LegendEntry>& entries, Align h, Align v, int scale) {
  Rect box = legend_size(entries, scale);
  const int w = box.width(), ht = box.height();
  box.left = x + anchor(w, h);
  box.top = y + anchor(ht, v);
  box.right = box.left + w;
  box.bottom = box.top + ht;
  c.fill(box, kWhite);
  c.frame(box, kGrey);
  int ty = box.top + kLegendPad;
  const int key = kLegendKey * scale;
  for (const auto& e : entries) {
    const int kx = box.left + kLegendPad, cy = ty + kCapHeight * scale / 2;
    switch (e.style) {
      case LegendEntry::Style::kLine: c.fill({kx, cy - scale, kx + key, cy + scale + 1}, e.colour); break;
      case LegendEntry::Style::kMarker:
        c.marker(kx + key / 2, cy, e.marker, kCapHeight * scale + 2, e.outline);
        c.marker(kx + key / 2, cy, e.marker, kCapHeight * scale - 2, e.colour);
        break;
      case LegendEntry::Style::kSwatch:
        c.fill({kx + key / 4, cy - kCapHeight * scale / 2 - 1, kx + key - key / 4, cy + kCapHeight * scale / 2 + 2}, e.outline);
        c.fill({kx + key / 4 + 1, cy - kCapHeight * scale / 2, kx + key - key / 4 - 1, cy + kCapHeight * scale / 2 + 1}, e.colour);
        break;
    }
    c.text(kx + key + kLegendPad, ty, e.label, kBlack, scale);
    ty += kLineHeight * scale;
  }
  return box;
}

void colour_bar(Canvas& c, const Rect& r, const std::function<Rgb(double)>& map,
                const std::function<double(double)>& position, const std::vector<double>& values, int decimals,
                const std::string& label, int scale) {
  const bool vertical = r.height() > r.width();
  const int n = vertical ? r.height() : r.width();
  for (int i = 0; i < n; ++i) {
    const double t = n > 1 ? static_cast<double>(i) / (n - 1) : 0.0;
    const Rgb col = map(t);
    if (vertical) c.fill({r.left, r.bottom - 1 - i, r.right, r.bottom - i}, col);
    else c.fill({r.left + i, r.top, r.left + i + 1, r.bottom}, col);
  }
  c.frame(r, kBlack);
  const int tick = 4, gap = 3;
  int widest = 0, last = -1000000;
  for (const double v : values) {
    const double t = std::clamp(position(v), 0.0, 1.0);
    const std::string s = format_tick(v, decimals);
    if (vertical) {
      const int y = r.bottom - 1 - static_cast<int>(std::lround(t * (n - 1)));
      c.fill({r.right, y, r.right + tick, y + 1}, kBlack);
      const Rect b = c.text(r.right + tick + gap, y, s, kBlack, scale, Align::kStart, Align::kCentre);
      widest = std::max(widest, b.width());
    } else {
      const int x = r.left + static_cast<int>(std::lround(t * (n - 1)));
      c.fill({x, r.bottom, x + 1, r.bottom + tick}, kBlack);
      const int w = text_width(s, scale);
      if (x - w / 2 <= last + kGlyphAdvance * scale) continue;
      last = c.text(x, r.bottom + tick + gap, s, kBlack, scale, Align::kCentre, Align::kStart).right;
    }
  }
  if (label.empty()) return;
  if (vertical)
    c.text_up(r.right + tick + gap + widest + 6 * scale, (r.top + r.bottom) / 2, label, kBlack, scale, Align::kCentre,
              Align::kStart);
  else
    c.text((r.left + r.right) / 2, r.bottom + tick + gap + (kCapHeight + 6) * scale, label, kBlack, scale, Align::kCentre,
           Align::kStart);
}

}  // namespace lex3d::plot
