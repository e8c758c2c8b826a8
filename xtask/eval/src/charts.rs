//! Charts of error against cost (plotters, SVG and PNG with an embedded DejaVu font) and Pareto fronts.

use anyhow::{anyhow, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

use super::Row;

type Metric = (&'static str, fn(&Row) -> f64);

/// Error metrics, one chart row each.
pub const ERRORS: [Metric; 3] = [
    ("lightmap rel. RMSE", |r| r.lightmap_rel_rmse),
    ("image rel. RMSE", |r| r.image_rel_rmse),
    ("mean FLIP", |r| r.flip),
];

/// Costs, one chart column each.
pub const COSTS: [Metric; 3] = [
    ("bake time (s)", |r| r.bake_s),
    ("frame time (ms, 1024x768)", |r| r.frame_ms),
    ("archive size (MiB)", |r| r.archive_bytes as f64 / 1048576.0),
];

/// Indices of the non-dominated points (lower cost and lower error are better), by cost.
pub fn pareto_front(pts: &[(f64, f64)]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..pts.len())
        .filter(|&i| pts[i].0.is_finite() && pts[i].1.is_finite())
        .collect();
    idx.sort_by(|&a, &b| pts[a].0.total_cmp(&pts[b].0).then(pts[a].1.total_cmp(&pts[b].1)));
    let mut front = Vec::new();
    let mut best = f64::INFINITY;
    for i in idx {
        if pts[i].1 < best {
            best = pts[i].1;
            front.push(i);
        }
    }
    front
}

/// Error of point `i` divided by the lowest error among the points that cost no more than it
/// (1 = on the front; 1.2 = 20 % more error than the front at equal cost).
pub fn ratio_to_front(pts: &[(f64, f64)], i: usize) -> f64 {
    let best = pts
        .iter()
        .filter(|p| p.0 <= pts[i].0 && p.1.is_finite())
        .map(|p| p.1)
        .fold(f64::INFINITY, f64::min);
    pts[i].1 / best
}

const GROUPS: [(&str, RGBColor); 8] = [
    ("auto", RGBColor(0, 0, 0)),
    ("entries", RGBColor(31, 119, 180)),
    ("clusters", RGBColor(255, 127, 14)),
    ("top_k", RGBColor(44, 160, 44)),
    ("resolution", RGBColor(214, 39, 40)),
    ("paths_per_entry", RGBColor(148, 103, 189)),
    ("vpl_disk_scale", RGBColor(140, 86, 75)),
    ("preset", RGBColor(227, 119, 194)),
];

fn colour(group: &str) -> RGBColor {
    GROUPS
        .iter()
        .find(|(g, _)| *g == group)
        .map(|(_, c)| *c)
        .unwrap_or(RGBColor(127, 127, 127))
}

fn log_range(values: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for v in values.filter(|v| v.is_finite() && *v > 0.0) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return -1.0..0.0;
    }
    // log10 coordinates on linear axes: evenly spaced labels even over a narrow range.
    let (lo, hi) = (lo.log10(), hi.log10());
    let pad = ((hi - lo) * 0.08).max(0.03);
    lo - pad..hi + pad
}

fn lg(p: (f64, f64)) -> (f64, f64) {
    (p.0.log10(), p.1.log10())
}

fn draw<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, scene: &str, rows: &[&Row]) -> Result<()> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("drawing the chart: {e:?}");
    root.fill(&WHITE).map_err(e)?;
    let title = format!(
        "{scene}: error against cost (filled dots: settings, line: Pareto front, labelled: automatic choice and presets)"
    );
    let root = root.titled(&title, ("sans-serif", 20)).map_err(e)?;
    let (body, legend) = root.split_vertically(root.dim_in_pixel().1 - 36);
    let panels = body.split_evenly((ERRORS.len(), COSTS.len()));
    for (pi, panel) in panels.iter().enumerate() {
        let (ename, ef) = ERRORS[pi / COSTS.len()];
        let (cname, cf) = COSTS[pi % COSTS.len()];
        let pts: Vec<(f64, f64)> = rows.iter().map(|r| (cf(r), ef(r))).collect();
        let xr = log_range(pts.iter().map(|p| p.0));
        let yr = log_range(pts.iter().map(|p| p.1));
        let mut chart = ChartBuilder::on(panel)
            .margin(8)
            .x_label_area_size(34)
            .y_label_area_size(52)
            .build_cartesian_2d(xr, yr)
            .map_err(e)?;
        chart
            .configure_mesh()
            .x_desc(format!("{cname}, log scale"))
            .y_desc(format!("{ename}, log scale"))
            .x_labels(6)
            .y_labels(6)
            .label_style(("sans-serif", 12))
            .axis_desc_style(("sans-serif", 13))
            .x_label_formatter(&|v| format_number(10f64.powf(*v)))
            .y_label_formatter(&|v| format_number(10f64.powf(*v)))
            .draw()
            .map_err(e)?;
        let front = pareto_front(&pts);
        chart
            .draw_series(LineSeries::new(
                front.iter().map(|&i| lg(pts[i])),
                ShapeStyle::from(&RGBColor(120, 120, 120)).stroke_width(2),
            ))
            .map_err(e)?;
        for (i, r) in rows.iter().enumerate() {
            let p = pts[i];
            if !(p.0 > 0.0 && p.1 > 0.0 && p.0.is_finite() && p.1.is_finite()) {
                continue;
            }
            let c = colour(&r.group);
            let size = if r.is_auto { 6 } else { 4 };
            let p = lg(p);
            chart
                .draw_series(std::iter::once(Circle::new(p, size, c.filled())))
                .map_err(e)?;
            if r.is_auto || r.group == "preset" {
                let text = if r.is_auto {
                    "auto".to_string()
                } else {
                    r.label.trim_start_matches("preset=").to_string()
                };
                let label =
                    EmptyElement::at(p) + Text::new(text, (7, -14), ("sans-serif", 13).into_font().color(&BLACK));
                chart.draw_series(std::iter::once(label)).map_err(e)?;
            }
        }
    }
    // Legend: the colour of each swept parameter.
    let mut x = 10;
    for (g, c) in GROUPS {
        legend.draw(&Circle::new((x + 5, 18), 5, c.filled())).map_err(e)?;
        legend
            .draw(&Text::new(g, (x + 14, 11), ("sans-serif", 14).into_font()))
            .map_err(e)?;
        x += 40 + 8 * g.len() as i32;
    }
    root.present().map_err(e)?;
    Ok(())
}

fn format_number(v: f64) -> String {
    if v >= 1000.0 {
        format!("{:.0}", (v / 10.0).round() * 10.0)
    } else if v >= 100.0 {
        format!("{v:.0}")
    } else if v >= 10.0 {
        format!("{v:.1}")
    } else if v >= 1.0 {
        format!("{v:.2}")
    } else {
        format!("{v:.3}")
    }
}

/// Writes `DIR/eval-SCENE.svg` and `.png` for every scene; returns the paths.
pub fn write_all(rows: &[Row], dir: &Path) -> Result<Vec<PathBuf>> {
    static FONT: std::sync::Once = std::sync::Once::new();
    FONT.call_once(|| {
        // DejaVu Sans (free licence) from the `dejavu` crate: PNG text needs no system fonts.
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular());
    });
    let mut scenes: Vec<&str> = Vec::new();
    for r in rows {
        if !scenes.contains(&r.scene.as_str()) {
            scenes.push(&r.scene);
        }
    }
    let size = (1500u32, 1150u32);
    let mut out = Vec::new();
    for scene in scenes {
        let rs: Vec<&Row> = rows.iter().filter(|r| r.scene == scene).collect();
        let svg = dir.join(format!("eval-{scene}.svg"));
        {
            let root = SVGBackend::new(&svg, size).into_drawing_area();
            draw(&root, scene, &rs)?;
        }
        let png = dir.join(format!("eval-{scene}.png"));
        let mut buf = vec![0u8; (size.0 * size.1 * 3) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut buf, size).into_drawing_area();
            draw(&root, scene, &rs)?;
        }
        image::RgbImage::from_raw(size.0, size.1, buf)
            .ok_or_else(|| anyhow!("PNG buffer size"))?
            .save(&png)
            .map_err(|e| anyhow!("writing {}: {e}", png.display()))?;
        out.push(svg);
        out.push(png);
    }
    Ok(out)
}
