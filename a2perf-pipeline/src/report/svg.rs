//! Hand-written SVG plots: radar charts per task (as in the paper's appendix) and training
//! curves with interquartile bands.

use std::collections::BTreeMap;
use std::fmt::Write;

use a2perf_core::LearningCurve;

use super::model::{Category, GroupReport};
use a2perf_metrics::numeric::percentile_sorted_lerp;

pub(super) const PALETTE: [&str; 8] = [
    "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf",
];

fn esc(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Radar chart of one task: one axis per metric that every algorithm has, each scaled to [0, 1]
/// across the algorithms with "better" pointing outwards (min–max; equal values sit at 1).
pub fn radar(task: &str, groups: &[&GroupReport]) -> String {
    let (w, h) = (760.0, 560.0);
    let (cx, cy, r) = (320.0, 290.0, 180.0);
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="sans-serif" font-size="11">"#
    );
    let _ = writeln!(s, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let _ = writeln!(
        s,
        r#"<text x="{cx}" y="24" text-anchor="middle" font-size="15">{}</text>"#,
        esc(task)
    );
    let axes: Vec<(&str, String, bool)> = groups
        .first()
        .map(|g| {
            g.metrics
                .iter()
                .filter(|m| {
                    groups.iter().all(|g| {
                        g.metric(&m.key)
                            .and_then(|x| x.mean)
                            .is_some_and(f64::is_finite)
                    })
                })
                .map(|m| {
                    let phase = match m.category {
                        Category::SystemTraining => "Train. ",
                        Category::SystemInference => "Inf. ",
                        _ => "",
                    };
                    let label = format!("{phase}{}", m.label);
                    (m.key.as_str(), label, m.higher_is_better)
                })
                .collect()
        })
        .unwrap_or_default();
    if axes.len() < 3 {
        let _ = writeln!(
            s,
            r#"<text x="{cx}" y="{cy}" text-anchor="middle">Fewer than 3 metrics available for every algorithm: no radar.</text></svg>"#
        );
        return s;
    }
    let n = axes.len();
    let angle =
        |i: usize| -std::f64::consts::FRAC_PI_2 + i as f64 * std::f64::consts::TAU / n as f64;
    for ring in 1..=4 {
        let rr = r * ring as f64 / 4.0;
        let pts: Vec<String> = (0..n)
            .map(|i| {
                format!(
                    "{:.1},{:.1}",
                    cx + rr * angle(i).cos(),
                    cy + rr * angle(i).sin()
                )
            })
            .collect();
        let _ = writeln!(
            s,
            r##"<polygon points="{}" fill="none" stroke="#ccc"/>"##,
            pts.join(" ")
        );
    }
    for (i, (_, label, higher)) in axes.iter().enumerate() {
        let (x, y) = (cx + r * angle(i).cos(), cy + r * angle(i).sin());
        let _ = writeln!(
            s,
            r##"<line x1="{cx}" y1="{cy}" x2="{x:.1}" y2="{y:.1}" stroke="#bbb"/>"##
        );
        let (lx, mut ly) = (
            cx + (r + 16.0) * angle(i).cos(),
            cy + (r + 16.0) * angle(i).sin(),
        );
        let anchor = if angle(i).cos() > 0.05 {
            "start"
        } else if angle(i).cos() < -0.05 {
            "end"
        } else {
            "middle"
        };
        // Top and bottom labels sit clear of their neighbours.
        if angle(i).sin() > 0.95 {
            ly += 10.0;
        } else if angle(i).sin() < -0.95 {
            ly -= 4.0;
        }
        let arrow = if *higher { "↑" } else { "↓" };
        let _ = writeln!(
            s,
            r#"<text x="{lx:.1}" y="{ly:.1}" text-anchor="{anchor}">{} {arrow}</text>"#,
            esc(label)
        );
    }
    let scaled = |key: &str, higher: bool, v: f64| -> f64 {
        let vals: Vec<f64> = groups
            .iter()
            .filter_map(|g| g.metric(key).and_then(|m| m.mean))
            .collect();
        let lo = vals.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = vals.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if hi - lo <= f64::EPSILON * hi.abs().max(1.0) {
            return 1.0;
        }
        let t = (v - lo) / (hi - lo);
        // Keep the worst algorithm visible just off the centre.
        0.1 + 0.9 * if higher { t } else { 1.0 - t }
    };
    for (gi, g) in groups.iter().enumerate() {
        let color = PALETTE[gi % PALETTE.len()];
        let pts: Vec<String> = axes
            .iter()
            .enumerate()
            .map(|(i, (key, _, higher))| {
                let v = g.metric(key).and_then(|m| m.mean).unwrap_or(f64::NAN);
                let rr = r * scaled(key, *higher, v);
                format!(
                    "{:.1},{:.1}",
                    cx + rr * angle(i).cos(),
                    cy + rr * angle(i).sin()
                )
            })
            .collect();
        let _ = writeln!(
            s,
            r#"<polygon points="{}" fill="{color}" fill-opacity="0.15" stroke="{color}" stroke-width="2"/>"#,
            pts.join(" ")
        );
        let ly = 50.0 + 18.0 * gi as f64;
        let _ = writeln!(
            s,
            r#"<rect x="620" y="{:.0}" width="12" height="12" fill="{color}"/><text x="638" y="{:.0}">{}</text>"#,
            ly - 10.0,
            ly,
            esc(&g.algorithm.to_uppercase())
        );
    }
    let _ = writeln!(
        s,
        r##"<text x="{cx}" y="{}" text-anchor="middle" fill="#666">Each axis min–max scaled across algorithms; outward is better.</text>"##,
        h - 12.0
    );
    s.push_str("</svg>\n");
    s
}

/// (step, q25, median, q75).
type QuartilePoint = (f64, f64, f64, f64);

pub(super) fn nice_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let span = (hi - lo).max(1e-12);
    let raw = span / 5.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| span / s <= 6.0)
        .unwrap_or(10.0 * mag);
    let mut t = (lo / step).ceil() * step;
    let mut out = Vec::new();
    while t <= hi + step * 1e-9 && out.len() < 12 {
        out.push(t);
        t += step;
    }
    out
}

pub(super) fn tick_label(v: f64) -> String {
    let v = if v.abs() < 1e-12 { 0.0 } else { v };
    if v != 0.0 && (v.abs() >= 1e5 || v.abs() < 1e-2) {
        format!("{v:.1e}")
    } else if v.fract() == 0.0 {
        format!("{v:.0}")
    } else {
        format!("{v:.2}")
    }
}

/// The ranges a plot of points spanning `x` × `y` draws: an empty range widened, `y` padded
/// by 5% so that no line sits on the frame.
pub(super) fn plot_ranges(
    (x0, mut x1): (f64, f64),
    (mut y0, mut y1): (f64, f64),
) -> ((f64, f64), (f64, f64)) {
    if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    if y1 - y0 < 1e-9 {
        y0 -= 0.5;
        y1 += 0.5;
    }
    let pad = 0.05 * (y1 - y0);
    ((x0, x1), (y0 - pad, y1 + pad))
}

/// A plot's frame (left, top, width, height), its ticks and the horizontal grid, for data
/// ranges `x` × `y` mapped to the page by `px`, `py`.
pub(super) fn frame(
    s: &mut String,
    (l, t, pw, ph): (f64, f64, f64, f64),
    (x0, x1): (f64, f64),
    (y0, y1): (f64, f64),
    px: &dyn Fn(f64) -> f64,
    py: &dyn Fn(f64) -> f64,
) {
    let _ = writeln!(
        s,
        r##"<rect x="{l}" y="{t}" width="{pw}" height="{ph}" fill="none" stroke="#444"/>"##
    );
    for v in nice_ticks(x0, x1) {
        let x = px(v);
        let _ = writeln!(
            s,
            r##"<line x1="{x:.1}" y1="{:.1}" x2="{x:.1}" y2="{:.1}" stroke="#444"/><text x="{x:.1}" y="{:.1}" text-anchor="middle">{}</text>"##,
            t + ph,
            t + ph + 5.0,
            t + ph + 18.0,
            tick_label(v)
        );
    }
    for v in nice_ticks(y0, y1) {
        let y = py(v);
        let _ = writeln!(
            s,
            r##"<line x1="{:.1}" y1="{y:.1}" x2="{l}" y2="{y:.1}" stroke="#444"/><line x1="{l}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#eee"/><text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"##,
            l - 5.0,
            l + pw,
            l - 8.0,
            y + 4.0,
            tick_label(v)
        );
    }
}

/// Training curves of one task: per algorithm the median evaluation return over seeds at each
/// evaluation step, with the interquartile range shaded. `groups` are the task's algorithms,
/// each with the learning curves of its seeds.
pub fn curves(task: &str, groups: &[(&str, Vec<&LearningCurve>)]) -> String {
    let (w, h) = (720.0, 440.0);
    let (l, r, t, b) = (70.0, 150.0, 40.0, 50.0);
    let (pw, ph) = (w - l - r, h - t - b);
    // Per algorithm: step -> (q25, median, q75).
    let mut series: Vec<(String, Vec<QuartilePoint>)> = Vec::new();
    for (algorithm, seed_curves) in groups {
        let mut at: BTreeMap<u64, Vec<f64>> = BTreeMap::new();
        for curve in seed_curves {
            for p in &curve.points {
                if p.mean_return.is_finite() {
                    at.entry(p.env_steps).or_default().push(p.mean_return);
                }
            }
        }
        let pts = at
            .into_iter()
            .map(|(step, mut v)| {
                v.sort_by(f64::total_cmp);
                (
                    step as f64,
                    percentile_sorted_lerp(&v, 25.0),
                    percentile_sorted_lerp(&v, 50.0),
                    percentile_sorted_lerp(&v, 75.0),
                )
            })
            .collect();
        series.push((algorithm.to_string(), pts));
    }
    let all = series.iter().flat_map(|(_, p)| p.iter());
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for &(x, lo, _, hi) in all {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(lo);
        y1 = y1.max(hi);
    }
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="sans-serif" font-size="11">"#
    );
    let _ = writeln!(s, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let _ = writeln!(
        s,
        r#"<text x="{:.0}" y="22" text-anchor="middle" font-size="15">{} — evaluation return (median, IQR over seeds)</text>"#,
        l + pw / 2.0,
        esc(task)
    );
    if !x0.is_finite() || !y0.is_finite() {
        let _ = writeln!(
            s,
            r#"<text x="{:.0}" y="{:.0}" text-anchor="middle">No curve points.</text></svg>"#,
            w / 2.0,
            h / 2.0
        );
        return s;
    }
    let ((x0, x1), (y0, y1)) = plot_ranges((x0, x1), (y0, y1));
    let px = |x: f64| l + (x - x0) / (x1 - x0) * pw;
    let py = |y: f64| t + ph - (y - y0) / (y1 - y0) * ph;
    frame(&mut s, (l, t, pw, ph), (x0, x1), (y0, y1), &px, &py);
    let _ = writeln!(
        s,
        r#"<text x="{:.0}" y="{:.0}" text-anchor="middle">environment steps</text>"#,
        l + pw / 2.0,
        h - 12.0
    );
    let _ = writeln!(
        s,
        r#"<text transform="translate(16,{:.0}) rotate(-90)" text-anchor="middle">return</text>"#,
        t + ph / 2.0
    );
    for (i, (name, pts)) in series.iter().enumerate() {
        let color = PALETTE[i % PALETTE.len()];
        if pts.is_empty() {
            continue;
        }
        let upper: Vec<String> = pts
            .iter()
            .map(|p| format!("{:.1},{:.1}", px(p.0), py(p.3)))
            .collect();
        let lower: Vec<String> = pts
            .iter()
            .rev()
            .map(|p| format!("{:.1},{:.1}", px(p.0), py(p.1)))
            .collect();
        let _ = writeln!(
            s,
            r#"<polygon points="{} {}" fill="{color}" fill-opacity="0.2" stroke="none"/>"#,
            upper.join(" "),
            lower.join(" ")
        );
        let line: Vec<String> = pts
            .iter()
            .map(|p| format!("{:.1},{:.1}", px(p.0), py(p.2)))
            .collect();
        let _ = writeln!(
            s,
            r#"<polyline points="{}" fill="none" stroke="{color}" stroke-width="2"/>"#,
            line.join(" ")
        );
        let ly = t + 14.0 + 18.0 * i as f64;
        let _ = writeln!(
            s,
            r#"<rect x="{:.0}" y="{:.0}" width="12" height="12" fill="{color}"/><text x="{:.0}" y="{:.0}">{}</text>"#,
            l + pw + 12.0,
            ly - 10.0,
            l + pw + 30.0,
            ly,
            esc(&name.to_uppercase())
        );
    }
    s.push_str("</svg>\n");
    s
}
