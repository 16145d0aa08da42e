//! Hand-drawn pictures of a placement: congestion heatmap, hard macros, soft macros, ports, as
//! SVG ([`render_svg`]) or as an RGB frame ([`render_rgb`], what the environment's `rgb_array`
//! render mode returns).

use std::fmt::Write as _;

use a2perf_core::render::{Canvas, Frame};

use crate::cost::PlacementCost;
use crate::netlist::NodeKind;

/// Pixels on the longer canvas side of the environment's `rgb_array` frames.
pub const RGB_SIZE: usize = 400;

/// Pixels on the longer canvas side of the environment's `svg` frames: the default of
/// `a2perf circuit render --size`, so that the two pictures of a placement are the same.
pub const SVG_SIZE: f64 = 800.0;

const WHITE: [u8; 3] = [0xff, 0xff, 0xff];
const BLACK: [u8; 3] = [0, 0, 0];
const OUTLINE: [u8; 3] = [0x33, 0x33, 0x33];
const SOFT_MACRO: [u8; 3] = [0x6f, 0xa8, 0xdc];
const HARD_MACRO: [u8; 3] = [0xe6, 0x91, 0x38];
const PORT: [u8; 3] = [0x38, 0x76, 0x1d];

/// Rasterizes `cost`'s current placement into an RGB frame `px` pixels on the longer canvas side
/// (at least 1 and at most 16384): the elements of [`render_svg`] in its colours and order
/// (white canvas with a black border, congestion heatmap, soft macros, placed hard macros,
/// ports) without its caption line.
///
/// ```
/// use a2perf_circuit::{generate, GeneratorConfig, PlacementCost, render::render_rgb};
/// use a2perf_core::render::Frame;
/// let g = generate(&GeneratorConfig::small(), 0);
/// let mut cost = PlacementCost::new(&g.netlist, g.settings.clone()).unwrap();
/// let Frame::Rgb { height, width, data } = render_rgb(&mut cost, 200) else { unreachable!() };
/// assert_eq!(height.max(width), 200);
/// assert_eq!(data.len(), height * width * 3);
/// ```
pub fn render_rgb(cost: &mut PlacementCost, px: usize) -> Frame {
    let px = px.clamp(1, 1 << 14);
    let (cw, ch) = {
        let s = cost.settings();
        (s.canvas_width, s.canvas_height)
    };
    let longer = cw.max(ch);
    let scale = if longer > 0.0 && longer.is_finite() {
        px as f64 / longer
    } else {
        0.0
    };
    let (wpx, hpx) = (cw * scale, ch * scale);
    let mut canvas = Canvas::new(wpx.round() as usize, hpx.round() as usize, WHITE);
    // Canvas coordinates: y points up; the picture's down.
    let fy = |y: f64| hpx - y * scale;
    let (gw, gh) = congestion_cell_size(cost);
    for c in congested_cells(cost) {
        canvas.fill_rect(
            c.col as f64 * gw * scale,
            fy((c.row + 1) as f64 * gh),
            (c.col + 1) as f64 * gw * scale,
            fy(c.row as f64 * gh),
            [255, c.shade, c.shade],
            0.6,
        );
    }
    let node = |canvas: &mut Canvas, i: usize, fill: [u8; 3], alpha: f64| {
        let (x, y) = cost.position(i);
        let (w, h) = cost.size(i);
        let (x0, x1) = ((x - w / 2.0) * scale, (x + w / 2.0) * scale);
        let (y0, y1) = (fy(y + h / 2.0), fy(y - h / 2.0));
        canvas.fill_rect(x0, y0, x1, y1, fill, alpha);
        canvas.stroke_rect(x0, y0, x1, y1, OUTLINE);
    };
    for i in 0..cost.num_nodes() {
        if matches!(cost.kind(i), NodeKind::SoftMacro | NodeKind::StdCell) {
            node(&mut canvas, i, SOFT_MACRO, 0.45);
        }
    }
    for &i in cost.hard_macros() {
        let i = i as usize;
        if cost.is_placed(i) {
            node(&mut canvas, i, HARD_MACRO, 0.85);
        }
    }
    for i in 0..cost.num_nodes() {
        if cost.kind(i) == NodeKind::Port {
            let (x, y) = cost.position(i);
            canvas.disc(x * scale, fy(y), 2.0, PORT);
        }
    }
    canvas.stroke_rect(0.0, 0.0, wpx, hpx, BLACK);
    canvas.into_frame()
}

/// A congestion-grid cell with congestion, as both pictures draw it.
struct CongestedCell {
    col: usize,
    row: usize,
    /// The larger of the cell's horizontal and vertical congestion.
    value: f64,
    /// Green and blue of its colour: 255 for none, 0 for the most congested cell.
    shade: u8,
}

/// The width and height of a congestion-grid cell (canvas units).
fn congestion_cell_size(cost: &PlacementCost) -> (f64, f64) {
    let s = cost.settings();
    let (cols, rows) = cost.congestion_grid();
    (s.canvas_width / cols as f64, s.canvas_height / rows as f64)
}

/// The cells of `cost`'s congestion grid that carry congestion, row by row.
fn congested_cells(cost: &mut PlacementCost) -> Vec<CongestedCell> {
    let (cols, rows) = cost.congestion_grid();
    let (hmap, vmap) = cost.congestion_maps();
    let maxc = hmap
        .iter()
        .zip(vmap)
        .map(|(h, v)| h.max(*v))
        .fold(0.0f64, f64::max);
    let mut out = Vec::new();
    for row in 0..rows {
        for col in 0..cols {
            let i = row * cols + col;
            let value = hmap[i].max(vmap[i]);
            if value <= 0.0 || maxc <= 0.0 {
                continue;
            }
            let t = (value / maxc).clamp(0.0, 1.0);
            out.push(CongestedCell {
                col,
                row,
                value,
                shade: (255.0 * (1.0 - t)) as u8,
            });
        }
    }
    out
}

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
    let (gw, gh) = congestion_cell_size(cost);
    s.push_str("<g id=\"congestion\">\n");
    for c in congested_cells(cost) {
        let _ = writeln!(
            s,
            "<rect x=\"{:.2}\" y=\"{:.2}\" width=\"{:.2}\" height=\"{:.2}\" fill=\"rgb(255,{},{})\" fill-opacity=\"0.6\"><title>congestion {:.4}</title></rect>",
            c.col as f64 * gw * scale,
            fy((c.row + 1) as f64 * gh),
            gw * scale,
            gh * scale,
            c.shade,
            c.shade,
            c.value
        );
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

#[cfg(test)]
mod tests {
    use a2perf_core::{Action, Env, EnvError, Frame, Observation, Step};

    use super::*;
    use crate::env::{CircuitEnv, CircuitEnvConfig};
    use crate::generator::{GeneratorConfig, generate};

    fn env() -> (CircuitEnv, crate::netlist::Netlist) {
        let g = generate(&GeneratorConfig::small(), 0);
        let env = CircuitEnv::new(
            &g.netlist,
            Some(&g.placement),
            g.settings.clone(),
            CircuitEnvConfig::default(),
        )
        .unwrap();
        (env, g.netlist)
    }

    fn rgb(frame: Frame) -> (usize, usize, Vec<u8>) {
        match frame {
            Frame::Rgb {
                height,
                width,
                data,
            } => (height, width, data),
            Frame::Text(_) => panic!("expected an rgb frame"),
        }
    }

    /// The first legal action of `obs`.
    fn first_legal(obs: &Observation) -> Action {
        let mask = obs.action_mask.as_ref().unwrap();
        Action::Discrete(mask.iter().position(|m| *m).unwrap())
    }

    #[test]
    fn rgb_frames_have_the_canvas_proportions_and_show_each_placed_macro() {
        let (mut env, _) = env();
        let obs = env.reset(Some(0)).unwrap();
        let (h, w, first) = rgb(env.render("rgb_array").unwrap());
        let (cw, ch) = {
            let s = env.cost().settings();
            (s.canvas_width, s.canvas_height)
        };
        assert_eq!(h.max(w), RGB_SIZE);
        assert_eq!(w, (cw * RGB_SIZE as f64 / cw.max(ch)).round() as usize);
        assert_eq!(first.len(), h * w * 3);
        // White canvas with a black border.
        assert_eq!(&first[..3], &[0, 0, 0]);
        assert!(first.chunks(3).any(|p| p == [255, 255, 255]));
        let node = env.order()[0];
        env.step(&first_legal(&obs)).unwrap();
        let (_, _, second) = rgb(env.render("rgb_array").unwrap());
        assert!(first != second, "placing a macro changes the frame");
        // The macro's centre pixel now carries its fill.
        let scale = RGB_SIZE as f64 / cw.max(ch);
        let (x, y) = env.cost().position(node);
        let (px, py) = ((x * scale) as usize, ((ch - y) * scale) as usize);
        let k = (py.min(h - 1) * w + px.min(w - 1)) * 3;
        assert_ne!(first[k..k + 3], second[k..k + 3]);
        let [r, g, b] = [second[k], second[k + 1], second[k + 2]];
        assert!(r > g && g > b, "orange-ish fill, got {r},{g},{b}");
    }

    /// One episode of first-legal actions; with `render`, every state's frames (both modes).
    fn episode(render: bool) -> (Vec<Step>, Vec<Frame>, Frame) {
        let (mut env, _) = env();
        let mut obs = env.reset(Some(3)).unwrap();
        let (mut steps, mut frames) = (Vec::new(), Vec::new());
        loop {
            if render {
                frames.push(env.render("rgb_array").unwrap());
                frames.push(env.render("svg").unwrap());
                assert!(frames[frames.len() - 2] == env.render("rgb_array").unwrap());
            }
            let step = env.step(&first_legal(&obs)).unwrap();
            obs = step.observation.clone();
            steps.push(step);
            if steps.last().unwrap().done() {
                let last = env.render("rgb_array").unwrap();
                return (steps, frames, last);
            }
        }
    }

    #[test]
    fn frames_are_deterministic_and_rendering_does_not_change_the_episode() {
        let (steps, frames, last) = episode(true);
        let (steps_again, frames_again, last_again) = episode(true);
        assert!(
            frames == frames_again && last == last_again,
            "same episode, same frames"
        );
        let (quiet, none, last_quiet) = episode(false);
        assert!(none.is_empty());
        assert_eq!(steps, quiet, "rendering changed the episode");
        assert_eq!(steps, steps_again);
        assert!(last == last_quiet);
        // Every placement changed the picture.
        for pair in frames.chunks(2).collect::<Vec<_>>().windows(2) {
            assert!(pair[0][0] != pair[1][0] && pair[0][1] != pair[1][1]);
        }
    }

    #[test]
    fn svg_is_what_the_cli_draws_for_the_placement() {
        let (mut env, netlist) = env();
        let mut obs = env.reset(Some(0)).unwrap();
        let Frame::Text(svg) = env.render("svg").unwrap() else {
            panic!("svg is text");
        };
        assert_eq!(svg, render_svg(env.cost_mut(), &netlist.name, SVG_SIZE));
        loop {
            let step = env.step(&first_legal(&obs)).unwrap();
            if step.done() {
                assert!(step.reward < 0.0 && step.info.get("infeasible") == Some(0.0));
                break;
            }
            obs = step.observation;
        }
        let Frame::Text(svg) = env.render("svg").unwrap() else {
            panic!("svg is text");
        };
        // `a2perf circuit render` on the finished placement: a fresh cost model with the `.plc`.
        let mut fresh = PlacementCost::new(&netlist, env.cost().settings().clone()).unwrap();
        fresh
            .apply_placement(&env.cost().to_placement(Vec::new()))
            .unwrap();
        assert_eq!(svg, render_svg(&mut fresh, &netlist.name, SVG_SIZE));
        assert!(svg.contains(&format!("<title>{}</title>", netlist.name)));
    }

    #[test]
    fn unknown_modes_name_the_supported_ones() {
        let (mut env, _) = env();
        assert_eq!(env.render_modes(), &["rgb_array", "svg"]);
        let err = env.render("human").unwrap_err();
        assert!(matches!(err, EnvError::InvalidParameter { .. }));
        let msg = err.to_string();
        assert!(
            msg.contains("`human`") && msg.contains("rgb_array, svg"),
            "{msg}"
        );
    }
}
