// Raster pictures for the command's PNGs: a canvas with lines, markers and text in a built-in
// bitmap font, and the parts of a chart (axes with ticks and labels, legend, colour bar).
// Drawing only: the caller hands canvas.rgb() to io::write_png_rgb.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace lex3d::plot {

struct Rgb {
  std::uint8_t r = 0, g = 0, b = 0;
  bool operator==(const Rgb& o) const { return r == o.r && g == o.g && b == o.b; }
  bool operator!=(const Rgb& o) const { return !(*this == o); }
};

inline constexpr Rgb kWhite{255, 255, 255};
inline constexpr Rgb kBlack{0, 0, 0};
inline constexpr Rgb kGrey{128, 128, 128};
inline constexpr Rgb kLightGrey{225, 225, 225};

/// The built-in font: glyphs 5 pixels wide on a 6-pixel advance, 7 rows above the baseline
/// and 2 below it, each pixel drawn as scale x scale.
inline constexpr int kGlyphAdvance = 6;
inline constexpr int kCapHeight = 7;
inline constexpr int kLineHeight = 11;  ///< baseline to baseline, scale 1

/// Width in pixels of s at this scale (no trailing gap).
int text_width(const std::string& s, int scale = 1);

enum class Align { kStart, kCentre, kEnd };
enum class Marker { kSquare, kCircle, kCross, kPlus, kDiamond };

struct Rect {
  int left = 0, top = 0, right = 0, bottom = 0;  ///< right and bottom exclusive
  int width() const { return right - left; }
  int height() const { return bottom - top; }
};

class Canvas {
 public:
  Canvas(int width, int height, Rgb background = kWhite);
  int width() const { return width_; }
  int height() const { return height_; }
  /// Row-major 8-bit RGB, width * height * 3 bytes.
  const std::vector<std::uint8_t>& rgb() const { return rgb_; }
  Rgb pixel(int x, int y) const;
  /// Every drawing call clips to the canvas.
  void set(int x, int y, Rgb c);
  void fill(const Rect& r, Rgb c);
  void frame(const Rect& r, Rgb c, int thickness = 1);
  void line(double x0, double y0, double x1, double y1, Rgb c, int thickness = 1);
  /// A marker of this outer size (pixels) centred on (x, y).
  void marker(int x, int y, Marker m, int size, Rgb c);
  /// Text whose box (text_width x kCapHeight*scale, the cap height) is anchored at (x, y):
  /// h over its width, v over its cap height. Returns the box.
  Rect text(int x, int y, const std::string& s, Rgb c, int scale = 1, Align h = Align::kStart,
            Align v = Align::kStart);
  /// The same turned a quarter counter-clockwise (read from bottom to top): h along the text
  /// (upwards), v across it.
  Rect text_up(int x, int y, const std::string& s, Rgb c, int scale = 1, Align h = Align::kCentre,
               Align v = Align::kCentre);

 private:
  int width_, height_;
  std::vector<std::uint8_t> rgb_;
};

/// Ticks at a round step (1, 2 or 5 times a power of ten, at least min_step) that puts at most
/// max_ticks in [lo, hi]; decimals is what the step needs to print exactly.
struct Ticks {
  double step = 1.0;
  int decimals = 0;
  std::vector<double> values;
};
Ticks nice_ticks(double lo, double hi, int max_ticks, double min_step = 0.0);
std::string format_tick(double v, int decimals);

/// A chart: data ranges [x0, x1] and [y0, y1] drawn in the pixel rectangle area (y upwards
/// unless y_down, as a matrix's rows are).
class Chart {
 public:
  Chart(Canvas& canvas, Rect area, double x0, double x1, double y0, double y1, bool y_down = false);
  double px(double x) const;
  double py(double y) const;
  const Rect& area() const { return area_; }
  /// Frame, ticks outside the area with their labels, optional light grid lines, the axis
  /// labels (x below, y turned up on the left). Tick labels that would touch are thinned.
  void axes(const Ticks& xt, const Ticks& yt, const std::string& xlabel, const std::string& ylabel,
            bool grid, int scale = 1);
  void polyline(const std::vector<double>& xs, const std::vector<double>& ys, Rgb c, int thickness = 1);

 private:
  Canvas& c_;
  Rect area_;
  double x0_, x1_, y0_, y1_;
  bool y_down_;
};

/// A chart's title: centred above area, scale 2, shrunk to scale 1 when it does not fit.
void title(Canvas& c, const Rect& area, int y, const std::string& s);

struct LegendEntry {
  enum class Style { kLine, kMarker, kSwatch } style = Style::kLine;
  std::string label;
  Rgb colour;
  Marker marker = Marker::kSquare;
  Rgb outline = kBlack;  ///< marker and swatch outline (same as colour: none)
};
/// A boxed legend with its corner h/v anchored at (x, y); returns its box.
Rect legend(Canvas& c, int x, int y, const std::vector<LegendEntry>& entries, Align h, Align v, int scale = 1);
/// Its size, to place it before drawing.
Rect legend_size(const std::vector<LegendEntry>& entries, int scale = 1);

/// A colour bar in r (vertical when taller than wide: t = 0 at the bottom; else t = 0 on the
/// left), coloured by map(t), t in [0, 1]; ticks at the values, placed at t = position(v),
/// labelled with decimals, and the label beside (right of a vertical bar, under a horizontal one).
void colour_bar(Canvas& c, const Rect& r, const std::function<Rgb(double)>& map,
                const std::function<double(double)>& position, const std::vector<double>& values, int decimals,
                const std::string& label, int scale = 1);

}  // namespace lex3d::plot
