// The command's raster plotting: font, text placement, ticks, chart mapping, legend, colour bar.

#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "plot.hpp"

using namespace lex3d::plot;

namespace {

// Bounding box of the pixels that differ from the background (empty: right <= left).
Rect ink(const Canvas& c, const Rect& within, Rgb background = kWhite) {
  Rect r{1 << 30, 1 << 30, -(1 << 30), -(1 << 30)};
  for (int y = within.top; y < within.bottom; ++y)
    for (int x = within.left; x < within.right; ++x)
      if (c.pixel(x, y) != background) {
        r.left = std::min(r.left, x);
        r.top = std::min(r.top, y);
        r.right = std::max(r.right, x + 1);
        r.bottom = std::max(r.bottom, y + 1);
      }
  return r;
}

Rect whole(const Canvas& c) { return {0, 0, c.width(), c.height()}; }

int count(const Canvas& c, const Rect& within, Rgb colour) {
  int n = 0;
  for (int y = within.top; y < within.bottom; ++y)
    for (int x = within.left; x < within.right; ++x) n += c.pixel(x, y) == colour ? 1 : 0;
  return n;
}

}  // namespace

TEST(Plot, TextSetsPixelsOnlyInItsBox) {
  Canvas c(200, 60);
  const Rect box = c.text(20, 10, "Recall 0.5", kBlack, 1);
  EXPECT_EQ(box.left, 20);
  EXPECT_EQ(box.top, 10);
  EXPECT_EQ(box.width(), 10 * kGlyphAdvance - 1);
  const Rect r = ink(c, whole(c));
  // 'R' starts in the first column and row; no descender in this string.
  EXPECT_EQ(r.left, 20);
  EXPECT_EQ(r.top, 10);
  EXPECT_LE(r.right, box.right);
  EXPECT_EQ(r.bottom, 10 + kCapHeight);
  // Twice the scale: twice the box, four times the ink.
  Canvas c2(400, 60);
  c2.text(20, 10, "Recall 0.5", kBlack, 2);
  const Rect r2 = ink(c2, whole(c2));
  EXPECT_EQ(r2.width(), 2 * r.width());
  EXPECT_EQ(r2.height(), 2 * r.height());
  EXPECT_EQ(count(c2, whole(c2), kBlack), 4 * count(c, whole(c), kBlack));
}

TEST(Plot, GlyphsDiffer) {
  // Every digit and letter draws a different pattern (a copy-paste slip in the font would not).
  const std::string chars = "0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz.%-+()/:=";
  std::vector<std::vector<std::uint8_t>> seen;
  for (const char ch : chars) {
    Canvas c(8, 12);
    c.text(1, 1, std::string(1, ch), kBlack);
    EXPECT_GT(count(c, whole(c), kBlack), 0) << ch;
    for (std::size_t i = 0; i < seen.size(); ++i) EXPECT_NE(seen[i], c.rgb()) << ch << " looks like " << chars[i];
    seen.push_back(c.rgb());
  }
}

TEST(Plot, DescendersHangBelowTheBaseline) {
  Canvas c(40, 30);
  c.text(2, 2, "gy", kBlack);
  EXPECT_GT(ink(c, whole(c)).bottom, 2 + kCapHeight);
}

TEST(Plot, CentredAndTurnedText) {
  Canvas c(200, 200);
  const Rect b = c.text(100, 50, "precision", kBlack, 1, Align::kCentre, Align::kCentre);
  EXPECT_NEAR((b.left + b.right) / 2.0, 100.0, 1.0);
  EXPECT_NEAR((b.top + b.bottom) / 2.0, 50.0, 1.0);
  Canvas u(200, 200);
  const Rect t = u.text_up(50, 100, "precision", kBlack, 1, Align::kCentre, Align::kCentre);
  EXPECT_EQ(t.width(), kCapHeight);
  EXPECT_EQ(t.height(), text_width("precision"));
  const Rect r = ink(u, whole(u));
  EXPECT_GT(r.height(), 5 * r.width());  // tall, not wide
  EXPECT_GE(r.top, t.top);
  EXPECT_LE(r.bottom, t.bottom);
  // Read bottom to top: the first letter 'p' (its descender on the right) is at the bottom.
  EXPECT_GT(ink(u, {r.left, t.bottom - kGlyphAdvance, r.right, t.bottom}).right, t.left + kCapHeight - 1);
}

TEST(Plot, NiceTicks) {
  const Ticks a = nice_ticks(0.0, 1.0, 11);
  ASSERT_EQ(a.values.size(), 11U);
  EXPECT_DOUBLE_EQ(a.step, 0.1);
  EXPECT_EQ(a.decimals, 1);
  EXPECT_EQ(format_tick(a.values[5], a.decimals), "0.5");
  const Ticks b = nice_ticks(0.0, 91.0, 8, 1.0);
  EXPECT_DOUBLE_EQ(b.step, 20.0);
  EXPECT_EQ(b.decimals, 0);
  EXPECT_EQ(b.values.back(), 80.0);
  const Ticks c = nice_ticks(0.0, 3.0, 10, 1.0);  // scan indices: never 0.5 steps
  EXPECT_DOUBLE_EQ(c.step, 1.0);
  const Ticks d = nice_ticks(-0.25, 0.25, 6);
  EXPECT_DOUBLE_EQ(d.step, 0.1);
  EXPECT_EQ(format_tick(d.values[2], d.decimals), "0.0");  // not "-0.0"
  EXPECT_EQ(d.values.size(), 5U);
  const Ticks e = nice_ticks(0.0, 0.025, 6);
  EXPECT_EQ(e.decimals, 3);  // 0.005 steps
}

TEST(Plot, TickLabelSitsUnderItsValue) {
  Canvas c(400, 300);
  Chart ch(c, {60, 20, 380, 240}, 0.0, 1.0, 0.0, 1.0);
  EXPECT_NEAR(ch.px(0.5), 60 + 0.5 * 319, 1e-9);
  EXPECT_NEAR(ch.py(1.0), 20, 1e-9);
  EXPECT_NEAR(ch.py(0.0), 239, 1e-9);
  const Ticks t = nice_ticks(0.0, 1.0, 6);
  ch.axes(t, t, "", "", false);
  // The x tick label "0.4" is centred under x = 0.4, in the band below the axis; "0.5" is no tick.
  const int x = static_cast<int>(std::lround(ch.px(0.4)));
  const Rect band{x - 12, 240 + 5, x + 13, 240 + 25};  // below the 5-pixel tick
  const Rect r = ink(c, band);
  ASSERT_LT(r.left, r.right) << "no label under 0.4";
  EXPECT_NEAR((r.left + r.right) / 2.0, x, 2.0);
  // The same label drawn alone at that place gives the same pixels.
  Canvas ref(400, 300);
  const Rect want = ref.text(x, r.top, "0.4", kBlack, 1, Align::kCentre, Align::kStart);
  for (int yy = want.top; yy < want.bottom; ++yy)
    for (int xx = want.left; xx < want.right; ++xx) EXPECT_EQ(c.pixel(xx, yy), ref.pixel(xx, yy)) << xx << "," << yy;
  // The y label "0.4" is left of the axis at y = 0.4, vertically centred on it.
  const int y = static_cast<int>(std::lround(ch.py(0.4)));
  const Rect yl = ink(c, {0, y - 8, 55, y + 9});
  ASSERT_LT(yl.left, yl.right);
  EXPECT_NEAR((yl.top + yl.bottom) / 2.0, y, 1.5);
}

TEST(Plot, CrowdedTickLabelsAreThinned) {
  Canvas c(200, 100);
  Chart ch(c, {20, 10, 120, 60}, 0.0, 1000.0, 0.0, 1.0);
  Ticks t;
  t.decimals = 0;
  for (int k = 0; k <= 10; ++k) t.values.push_back(100.0 * k);  // labels up to "1000", ticks 10 px apart
  ch.axes(t, nice_ticks(0, 1, 3), "", "", false);
  // Columns of the label band under the axis: the runs of ink (labels) are fewer than the
  // ticks and separated by at least one glyph of white.
  const int top = 60 + 5 + 3, bottom = top + kCapHeight;
  std::vector<std::pair<int, int>> runs;
  for (int x = 0; x < 200; ++x) {
    bool any = false;
    for (int y = top; y < bottom; ++y) any = any || c.pixel(x, y) != kWhite;
    if (!any) continue;
    if (!runs.empty() && x - runs.back().second <= 2) runs.back().second = x;  // gaps inside a label
    else runs.emplace_back(x, x);
  }
  ASSERT_GE(runs.size(), 2U);
  EXPECT_LT(runs.size(), t.values.size());
  for (std::size_t i = 1; i < runs.size(); ++i) EXPECT_GE(runs[i].first - runs[i - 1].second, kGlyphAdvance);
}

TEST(Plot, LegendHoldsItsEntries) {
  Canvas c(300, 200);
  const std::vector<LegendEntry> e{{LegendEntry::Style::kLine, "lex3d", {200, 0, 0}},
                                   {LegendEntry::Style::kMarker, "threshold 0.25", {0, 0, 255}, Marker::kCircle}};
  const Rect box = legend(c, 290, 10, e, Align::kEnd, Align::kStart);
  EXPECT_EQ(box.right, 290);
  EXPECT_EQ(box.top, 10);
  EXPECT_GE(box.width(), text_width("threshold 0.25") + 20);
  EXPECT_GT(count(c, box, {200, 0, 0}), 10);
  EXPECT_GT(count(c, box, {0, 0, 255}), 5);
  EXPECT_EQ(count(c, {0, 0, box.left, 200}, {200, 0, 0}), 0);  // nothing drawn outside
}

TEST(Plot, ColourBarRunsFromLowToHigh) {
  Canvas c(120, 240);
  auto map = [](double t) { return Rgb{static_cast<std::uint8_t>(255 * t), 0, 0}; };
  colour_bar(c, {10, 20, 30, 220}, map, [](double v) { return v; }, {0.0, 0.5, 1.0}, 1, "score");
  EXPECT_LE(c.pixel(20, 218).r, 2);      // bottom: t = 0 (inside the frame)
  EXPECT_GE(c.pixel(20, 21).r, 253);     // top: t = 1
  EXPECT_NEAR(c.pixel(20, 120).r, 128, 3);
  // The "0.5" label is right of the bar, centred on the middle.
  const Rect r = ink(c, {34, 110, 60, 131});
  EXPECT_NEAR((r.top + r.bottom) / 2.0, 119.5, 1.5);
}

TEST(Plot, LinesClipAndMarkersCentre) {
  Canvas c(50, 50);
  c.line(-1e12, 0, 1e12, 0, kBlack);  // far outside: skipped, no endless loop
  c.line(-10, 25, 60, 25, kBlack);
  EXPECT_EQ(count(c, whole(c), kBlack), 50);
  Canvas m(50, 50);
  m.marker(25, 25, Marker::kSquare, 7, kBlack);
  const Rect r = ink(m, whole(m));
  EXPECT_EQ(r.left, 22);
  EXPECT_EQ(r.right, 29);
  EXPECT_EQ(r.top, 22);
}

// --- the pictures of place eval ---

#include "place_pictures.hpp"

TEST(PlacePictures, LongSequencesShareCells) {
  lex3d::cli::EvalPictures e;
  e.set_scans(1200);  // more scans than matrix pixels: 3 x 3 scans a cell
  EXPECT_EQ(e.k, 3U);
  EXPECT_EQ(e.cells, 400U);
  EXPECT_EQ(e.score.size(), 400U * 400U);
  e.in_database(1000, 10, false);
  EXPECT_EQ(e.score[333 * 400 + 3], 0.0F);
  e.set_score(1000, 10, 0.2);
  e.set_score(1001, 11, 0.4);
  e.set_score(1002, 9, 0.1);
  EXPECT_FLOAT_EQ(e.score[333 * 400 + 3], 0.4F);  // the highest of the cell
  EXPECT_TRUE(std::isnan(e.score[333 * 400 + 4]));
  e.in_database(1000, 12, true);
  EXPECT_EQ(e.revisit[333 * 400 + 4], 1);
  e.in_database(5000, 12, true);  // out of range: ignored
  const Canvas c = lex3d::cli::draw_score_matrix(e);
  EXPECT_EQ(c.width(), 760);
  EXPECT_EQ(c.height(), 720);
}

TEST(PlacePictures, ScoreMatrixMarksRevisits) {
  lex3d::cli::EvalPictures e;
  e.radius_m = 4;
  e.threshold = 0.25;
  e.set_scans(4);  // 140-pixel cells
  e.in_database(3, 0, true);
  e.in_database(3, 1, false);
  e.set_score(3, 1, 0.5);
  const Canvas c = lex3d::cli::draw_score_matrix(e);
  // Row 3, column 0: white (score 0) inside an orange outline; column 1: the darkest blue;
  // row 0: no database (grey).
  const int left = 84, top = 60, cs = 140;
  const Rgb centre0 = c.pixel(left + cs / 2, top + 3 * cs + cs / 2);
  EXPECT_EQ(centre0, kWhite);
  const Rgb edge0 = c.pixel(left + 1, top + 3 * cs + cs / 2);
  EXPECT_GT(edge0.r, 200);
  EXPECT_LT(edge0.b, 60);
  const Rgb centre1 = c.pixel(left + cs + cs / 2, top + 3 * cs + cs / 2);
  EXPECT_LT(centre1.r, 60);
  EXPECT_GT(centre1.b, centre1.r);
  const Rgb none = c.pixel(left + cs / 2, top + cs / 2);
  EXPECT_EQ(none.r, none.b);
  EXPECT_GT(none.r, 150);
  EXPECT_LT(none.r, 255);
}

TEST(PlacePictures, OperatingPointWhereItsRecallAndPrecisionMap) {
  lex3d::cli::EvalPictures e;
  e.method = "m";
  e.curve = {{1.01, 1.0, 0.0}, {0.5, 1.0, 0.5}, {0.2, 0.5, 0.75}};
  e.precision = 0.5;
  e.recall = 0.75;
  const Canvas c = lex3d::cli::draw_precision_recall(e);
  Canvas blank(640, 480);
  Chart ch(blank, {78, 52, 612, 408}, -0.02, 1.02, -0.02, 1.02);
  const int x = static_cast<int>(std::lround(ch.px(0.75))), y = static_cast<int>(std::lround(ch.py(0.5)));
  const Rgb mark = c.pixel(x, y);
  EXPECT_GT(mark.b, 150);
  EXPECT_LT(mark.r, 100);
  // The curve passes through (0.5, 1.0) in red.
  const Rgb on = c.pixel(static_cast<int>(std::lround(ch.px(0.25))), static_cast<int>(std::lround(ch.py(1.0))));
  EXPECT_GT(on.r, 150);
  EXPECT_LT(on.g, 80);
}
