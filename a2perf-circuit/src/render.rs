//! A hand-written SVG picture of a placement: congestion heatmap, hard macros, soft macros, ports.

use std::fmt::Write as _;

use crate::cost::PlacementCost;
use crate::netlist::NodeKind;

/// Renders `cost`'s current placement as SVG (`px` pixels on the longer side).
///
/// ```
/// use a2perf_circuit::{generate, GeneratorConfig, PlacementCost, render::render_svg};
/// let g = generate(&GeneratorConfig::small(), 0);
/// let mut cost = PlacementCost::new(&g.netlist, g.settings.clone()).unwrap();
/// let svg = render_svg(&mut cost, "demo", 400.0);
/// assert!(svg.starts_with("<svg") && svg.contains("</svg>"));
/// ```
pub fn render_svg(cost: &mut PlacementCost, title: &str, px: f64) -> String {
    let (cw, ch) = {
        let s = cost.settings();
        (s.canvas_width, s.canvas_height)
    };
    let scale = px / cw.max(ch);
    let (wpx, hpx) = (cw * scale, ch * scale);
    // SVG's y axis points down; the canvas's up.
    let fy = |y: f64| hpx - y * scale;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{:.0}\" height=\"{:.0}\" viewBox=\"0 0 {wpx:.2} {:.2}\">",
        wpx,
        hpx + 24.0,
        hpx + 24.0
    );
    let _ = writeln!(s, "<title>{}</title>", xml_escape(title));
    let _ = writeln!(
        s,
        "<rect x=\"0\" y=\"0\" width=\"{wpx:.2}\" height=\"{hpx:.2}\" fill=\"#ffffff\" stroke=\"#000\"/>"
    );
    let c = cost.costs();
    let (ccols, crows) = cost.congestion_grid();
    let (hmap, vmap) = cost.congestion_maps();
    let maxc = hmap
        .iter()
        .zip(vmap)
        .map(|(h, v)| h.max(*v))
        .fold(0.0f64, f64::max);
    let (gw, gh) = (cw / ccols as f64, ch / crows as f64);
    s.push_str("<g id=\"congestion\">\n");
    for r in 0..crows {
        for col in 0..ccols {
            let i = r * ccols + col;
            let v = hmap[i].max(vmap[i]);
            if v <= 0.0 || maxc <= 0.0 {
                continue;
            }
            let t = (v / maxc).clamp(0.0, 1.0);
            let _ = writeln!(
                s,
                "<rect x=\"{:.2}\" y=\"{:.2}\" width=\"{:.2}\" height=\"{:.2}\" fill=\"rgb(255,{},{})\" fill-opacity=\"0.6\"><title>congestion {v:.4}</title></rect>",
                col as f64 * gw * scale,
                fy((r + 1) as f64 * gh),
                gw * scale,
                gh * scale,
                (255.0 * (1.0 - t)) as u8,
                (255.0 * (1.0 - t)) as u8
            );
        }
    }
    s.push_str("</g>\n<g id=\"soft_macros\">\n");
    for i in 0..cost.num_nodes() {
        if matches!(cost.kind(i), NodeKind::SoftMacro | NodeKind::StdCell) {
            rect(&mut s, cost, i, scale, hpx, "#6fa8dc", "0.45");
        }
    }
    s.push_str("</g>\n<g id=\"hard_macros\">\n");
    for &i in cost.hard_macros() {
        let i = i as usize;
        if cost.is_placed(i) {
            rect(&mut s, cost, i, scale, hpx, "#e69138", "0.85");
        }
    }
    s.push_str("</g>\n<g id=\"ports\">\n");
    for i in 0..cost.num_nodes() {
        if cost.kind(i) == NodeKind::Port {
            let (x, y) = cost.position(i);
            let _ = writeln!(
                s,
                "<circle cx=\"{:.2}\" cy=\"{:.2}\" r=\"2\" fill=\"#38761d\"/>",
                x * scale,
                fy(y)
            );
        }
    }
    s.push_str("</g>\n");
    let _ = writeln!(
        s,
        "<text x=\"4\" y=\"{:.2}\" font-family=\"monospace\" font-size=\"12\">{}: wl {:.4} dens {:.4} cong {:.4} proxy {:.4}</text>",
        hpx + 16.0,
        xml_escape(title),
        c.wirelength_cost,
        c.density_cost,
        c.congestion_cost,
        c.proxy_cost
    );
    s.push_str("</svg>\n");
    s
}

fn rect(
    s: &mut String,
    cost: &PlacementCost,
    i: usize,
    scale: f64,
    hpx: f64,
    fill: &str,
    op: &str,
) {
    let (x, y) = cost.position(i);
    let (w, h) = cost.size(i);
    let _ = writeln!(
        s,
        "<rect x=\"{:.2}\" y=\"{:.2}\" width=\"{:.2}\" height=\"{:.2}\" fill=\"{fill}\" fill-opacity=\"{op}\" stroke=\"#333\" stroke-width=\"0.5\"/>",
        (x - w / 2.0) * scale,
        hpx - (y + h / 2.0) * scale,
        w * scale,
        h * scale
    );
}

fn xml_escape(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}
