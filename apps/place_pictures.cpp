#include "place_pictures.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace lex3d::cli {

namespace {

using plot::Align;
using plot::Canvas;
using plot::Chart;
using plot::LegendEntry;
using plot::Rect;
using plot::Rgb;

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

const Rgb kCurve{200, 30, 30};
const Rgb kOperating{30, 90, 200};
const Rgb kRevisit{240, 120, 0};
const Rgb kNotInDb{200, 200, 200};
const Rgb kAccepted{255, 255, 255};

// White (score 0) through light and mid blue to dark navy (the top of the bar).
Rgb blues(double t) {
  static const double stops[4][4] = {{0.0, 255, 255, 255}, {0.35, 140, 190, 225}, {0.7, 40, 110, 180}, {1.0, 8, 40, 100}};
  t = std::clamp(t, 0.0, 1.0);
  for (int i = 1; i < 4; ++i) {
    if (t > stops[i][0] && i < 3) continue;
    const double u = (t - stops[i - 1][0]) / (stops[i][0] - stops[i - 1][0]);
    auto mix = [&](int c) { return static_cast<std::uint8_t>(std::lround(stops[i - 1][c] + u * (stops[i][c] - stops[i - 1][c]))); };
    return {mix(1), mix(2), mix(3)};
  }
  return {8, 40, 100};
}

}  // namespace

void EvalPictures::set_scans(std::size_t n) {
  scans = n;
  k = std::max<std::size_t>(1, (n + kMatrixCells - 1) / kMatrixCells);
  cells = (n + k - 1) / k;
  score.assign(cells * cells, std::nanf(""));
  revisit.assign(cells * cells, 0);
}

void EvalPictures::in_database(std::size_t query, std::size_t scan, bool within_radius) {
  if (query >= scans || scan >= scans) return;
  const std::size_t c = query / k * cells + scan / k;
  if (!std::isfinite(score[c])) score[c] = 0.0F;
  if (within_radius) revisit[c] = 1;
}

void EvalPictures::set_score(std::size_t query, std::size_t scan, double s) {
  if (query >= scans || scan >= scans) return;
  const std::size_t c = query / k * cells + scan / k;
  score[c] = std::isfinite(score[c]) ? std::max(score[c], static_cast<float>(s)) : static_cast<float>(s);
}

Canvas draw_precision_recall(const EvalPictures& e) {
  Canvas c(640, 480);
  const Rect area{78, 52, 612, 408};
  plot::title(c, area, 10, "Precision-recall: " + e.data_name + ", true within " + fmt("%g", e.radius_m) + " m");
  c.text((area.left + area.right) / 2, 32,
         std::to_string(e.positives) + (e.positives == 1 ? " query" : " queries") + " with a true revisit; the curve runs over the score threshold",
         plot::kBlack, 1, Align::kCentre);
  // A little beyond [0, 1], so that a curve along precision 1 or recall 0 is not hidden by the frame.
  Chart ch(c, area, -0.02, 1.02, -0.02, 1.02);
  const plot::Ticks t = plot::nice_ticks(0.0, 1.0, 11);
  ch.axes(t, t, "recall (share of the queries with a revisit matched to it)", "precision (share of accepted matches that are true)",
          true);
  std::vector<double> xs, ys;
  for (const auto& p : e.curve) {
    xs.push_back(p[2]);
    ys.push_back(p[1]);
  }
  ch.polyline(xs, ys, kCurve, 2);
  const int ox = static_cast<int>(std::lround(ch.px(e.recall))), oy = static_cast<int>(std::lround(ch.py(e.precision)));
  c.marker(ox, oy, plot::Marker::kCircle, 11, plot::kBlack);
  c.marker(ox, oy, plot::Marker::kCircle, 8, kOperating);
  std::vector<LegendEntry> entries;
  entries.push_back({LegendEntry::Style::kLine, e.method + ": recall " + fmt("%.2f", e.recall_at_precision_1) + " at 100 % precision", kCurve});
  entries.push_back({LegendEntry::Style::kMarker,
                     "threshold " + fmt("%.2f", e.threshold) + ": precision " + fmt("%.2f", e.precision) + ", recall " +
                         fmt("%.2f", e.recall),
                     kOperating, plot::Marker::kCircle});
  if (e.curve.size() <= 1) entries.push_back({LegendEntry::Style::kSwatch, "no query had a database scan", plot::kWhite});
  plot::legend(c, area.left + 8, area.bottom - 8, entries, Align::kStart, Align::kEnd);
  return c;
}

Canvas draw_score_matrix(const EvalPictures& e) {
  Canvas c(760, 720);
  const int most = static_cast<int>(EvalPictures::kMatrixCells);  // pixels of the matrix side at most
  const std::size_t n = std::max<std::size_t>(e.scans, 1);
  const std::size_t k = e.k;
  const int nb = static_cast<int>(e.cells);
  const int cs = std::max(1, most / std::max(nb, 1));
  const int side = nb * cs;
  const Rect area{84, 60, 84 + side, 60 + side};
  plot::title(c, {0, 0, c.width(), 0}, 10, "Place scores: " + e.data_name + ", " + std::to_string(e.scans) + " scans");
  std::string sub = "each query against the scans at least " + fmt("%g", e.min_gap_s) + " s older";
  if (k > 1) sub += "; a cell is " + std::to_string(k) + " x " + std::to_string(k) + " scans (highest score)";
  c.text(c.width() / 2, 32, sub, plot::kBlack, 1, Align::kCentre);

  double top = 0;
  for (const float s : e.score)
    if (std::isfinite(s)) top = std::max(top, static_cast<double>(s));
  top = std::clamp(std::ceil(std::max(top, e.threshold) * 10.0 - 1e-9) / 10.0, 0.1, 1.0);
  const bool outline = cs >= 5;  // else a revisit cell is filled
  for (int bi = 0; bi < nb; ++bi)
    for (int bj = 0; bj < nb; ++bj) {
      const float v = e.score[static_cast<std::size_t>(bi) * e.cells + static_cast<std::size_t>(bj)];
      const bool any = std::isfinite(v);
      const bool revisit = e.revisit[static_cast<std::size_t>(bi) * e.cells + static_cast<std::size_t>(bj)] != 0;
      const double s = any ? static_cast<double>(v) : 0.0;
      const Rect cell{area.left + bj * cs, area.top + bi * cs, area.left + (bj + 1) * cs, area.top + (bi + 1) * cs};
      c.fill(cell, any ? blues(s / top) : kNotInDb);
      if (revisit) {
        if (outline) c.frame(cell, kRevisit, cs >= 9 ? 2 : 1);
        else c.fill(cell, kRevisit);
      }
    }
  const int dot = std::max(3, std::min(cs - 2, 7));
  for (const auto& [q, j] : e.accepted) {
    const int x = area.left + static_cast<int>(j / k) * cs + cs / 2, y = area.top + static_cast<int>(q / k) * cs + cs / 2;
    c.marker(x, y, plot::Marker::kCircle, dot + 2, plot::kBlack);
    c.marker(x, y, plot::Marker::kCircle, dot - 1, kAccepted);
  }
  Chart ch(c, area, -0.5, static_cast<double>(nb * k) - 0.5, -0.5, static_cast<double>(nb * k) - 0.5, true);
  const int max_ticks = std::max(2, side / 45);
  const plot::Ticks t = plot::nice_ticks(0.0, static_cast<double>(n - 1), max_ticks, 1.0);
  ch.axes(t, t, "database scan (index in the folder's order)", "query scan (index in the folder's order)", false);

  const Rect bar{area.right + 22, area.top, area.right + 40, area.bottom};
  const plot::Ticks bt = plot::nice_ticks(0.0, top, std::max(2, side / 40));
  plot::colour_bar(c, bar, blues, [&](double v) { return v / top; }, bt.values, bt.decimals,
                   "match score (accepted from " + fmt("%.2f", e.threshold) + ": black line)");
  if (e.threshold <= top) {
    const int y = bar.bottom - 1 - static_cast<int>(std::lround(e.threshold / top * (bar.height() - 1)));
    c.fill({bar.left - 4, y - 1, bar.right, y + 1}, plot::kBlack);
  }

  std::vector<LegendEntry> entries;
  entries.push_back({LegendEntry::Style::kSwatch,
                     outline ? "true revisit: database scan within " + fmt("%g", e.radius_m) + " m of the query (outlined)"
                             : "true revisit: database scan within " + fmt("%g", e.radius_m) + " m of the query (its score not shown)",
                     outline ? plot::kWhite : kRevisit, plot::Marker::kSquare, kRevisit});
  entries.push_back({LegendEntry::Style::kSwatch, "not in the query's database (newer than " + fmt("%g", e.min_gap_s) + " s before it)",
                     kNotInDb, plot::Marker::kSquare, kNotInDb});
  entries.push_back({LegendEntry::Style::kMarker, "accepted best match of the query (score " + fmt("%.2f", e.threshold) + " or more)",
                     kAccepted, plot::Marker::kCircle});
  plot::legend(c, area.left, area.bottom + 44, entries, Align::kStart, Align::kStart);
  return c;
}

}  // namespace lex3d::cli
