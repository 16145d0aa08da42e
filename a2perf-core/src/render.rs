//! Frames of [`Env::render`](crate::Env::render) and a small software rasterizer to draw them.
//!
//! [`Canvas`] draws filled rectangles (optionally translucent), rectangle outlines, lines and
//! discs into an RGB buffer. It is deliberately tiny and exact: no anti-aliasing, pixel coverage
//! decided by pixel centres, integer Bresenham lines, so a frame depends only on the scene.
//!
//! ```
//! use a2perf_core::render::{Canvas, Frame};
//! let mut c = Canvas::new(8, 4, [255, 255, 255]);
//! c.fill_rect(0.0, 0.0, 4.0, 4.0, [255, 0, 0], 1.0);
//! c.line(0.0, 3.0, 7.0, 3.0, [0, 0, 255], 1);
//! assert_eq!(c.pixel(1, 1), Some([255, 0, 0]));
//! assert_eq!(c.pixel(6, 3), Some([0, 0, 255]));
//! let Frame::Rgb { height, width, data } = c.into_frame() else { unreachable!() };
//! assert_eq!((height, width, data.len()), (4, 8, 4 * 8 * 3));
//! ```

/// What [`Env::render`](crate::Env::render) returns.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Frame {
    /// An RGB image, row-major `height × width × 3` bytes (Gymnasium's `rgb_array`).
    Rgb {
        /// Rows.
        height: usize,
        /// Columns.
        width: usize,
        /// `height * width * 3` bytes, row by row, each pixel `[r, g, b]`.
        data: Vec<u8>,
    },
    /// A text document (an SVG picture, an HTML page, …).
    Text(String),
}

/// An RGB drawing surface; `(0, 0)` is the top-left corner, `x` goes right and `y` down.
///
/// Coordinates are pixels as `f64`; a pixel `(i, j)` is covered by a shape when its centre
/// `(i + 0.5, j + 0.5)` is. Everything outside the canvas (and every non-finite coordinate) is
/// clipped away, so any input draws without panicking.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Canvas {
    width: usize,
    height: usize,
    data: Vec<u8>,
}

/// Lines longer than this many pixels after clipping cannot occur on a canvas of sane size; it
/// bounds the work of one [`Canvas::line`] call whatever its input.
const MAX_CANVAS_SIDE: usize = 1 << 14;

impl Canvas {
    /// A `width × height` canvas filled with `background` (each side at least 1 and at most
    /// 16384 pixels; other values are clamped into that range).
    pub fn new(width: usize, height: usize, background: [u8; 3]) -> Self {
        let width = width.clamp(1, MAX_CANVAS_SIDE);
        let height = height.clamp(1, MAX_CANVAS_SIDE);
        let mut data = Vec::with_capacity(width * height * 3);
        for _ in 0..width * height {
            data.extend_from_slice(&background);
        }
        Self {
            width,
            height,
            data,
        }
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// The colour of pixel `(x, y)`, `None` outside the canvas.
    pub fn pixel(&self, x: usize, y: usize) -> Option<[u8; 3]> {
        (x < self.width && y < self.height).then(|| {
            let k = (y * self.width + x) * 3;
            [self.data[k], self.data[k + 1], self.data[k + 2]]
        })
    }

    /// Paints pixel `(x, y)` with `color` at opacity `alpha` (0 = unchanged, 1 = `color`);
    /// outside the canvas nothing happens.
    pub fn blend(&mut self, x: i64, y: i64, color: [u8; 3], alpha: f64) {
        if x < 0 || y < 0 || x as usize >= self.width || y as usize >= self.height {
            return;
        }
        let k = (y as usize * self.width + x as usize) * 3;
        let a = if alpha.is_nan() {
            0.0
        } else {
            alpha.clamp(0.0, 1.0)
        };
        for (dst, &src) in self.data[k..k + 3].iter_mut().zip(&color) {
            let v = f64::from(*dst) * (1.0 - a) + f64::from(src) * a;
            *dst = v.round() as u8;
        }
    }

    /// The pixel range `[lo, hi)` whose centres lie in `[a, b)` along an axis of `n` pixels.
    fn span(a: f64, b: f64, n: usize) -> (i64, i64) {
        let lo = (a - 0.5).ceil();
        let hi = (b - 0.5).ceil();
        let clamp = |v: f64| v.clamp(0.0, n as f64) as i64;
        (clamp(lo), clamp(hi))
    }

    /// Fills the axis-aligned rectangle between corners `(x0, y0)` and `(x1, y1)` (in any order)
    /// with `color` at opacity `alpha`. A rectangle too small to cover any pixel centre still
    /// paints the pixel under its centre, so that nothing drawn disappears.
    pub fn fill_rect(&mut self, x0: f64, y0: f64, x1: f64, y1: f64, color: [u8; 3], alpha: f64) {
        if ![x0, y0, x1, y1].iter().all(|v| v.is_finite()) {
            return;
        }
        let (xa, xb) = (x0.min(x1), x0.max(x1));
        let (ya, yb) = (y0.min(y1), y0.max(y1));
        let (mut i0, mut i1) = Self::span(xa, xb, self.width);
        let (mut j0, mut j1) = Self::span(ya, yb, self.height);
        if i0 == i1 || j0 == j1 {
            // Thinner than a pixel along some axis: the pixel under the centre, if on the canvas.
            let (cx, cy) = (((xa + xb) / 2.0).floor(), ((ya + yb) / 2.0).floor());
            if i0 == i1 {
                if cx < 0.0 || cx >= self.width as f64 {
                    return;
                }
                (i0, i1) = (cx as i64, cx as i64 + 1);
            }
            if j0 == j1 {
                if cy < 0.0 || cy >= self.height as f64 {
                    return;
                }
                (j0, j1) = (cy as i64, cy as i64 + 1);
            }
        }
        for y in j0..j1 {
            for x in i0..i1 {
                self.blend(x, y, color, alpha);
            }
        }
    }

    /// Draws the one-pixel outline of the rectangle between `(x0, y0)` and `(x1, y1)`.
    pub fn stroke_rect(&mut self, x0: f64, y0: f64, x1: f64, y1: f64, color: [u8; 3]) {
        let (xa, xb) = (x0.min(x1), x0.max(x1));
        let (ya, yb) = (y0.min(y1), y0.max(y1));
        // The outline runs through the pixels just inside the rectangle's edges.
        let (l, r) = (xa + 0.5, (xb - 0.5).max(xa + 0.5));
        let (t, b) = (ya + 0.5, (yb - 0.5).max(ya + 0.5));
        self.line(l, t, r, t, color, 1);
        self.line(l, b, r, b, color, 1);
        self.line(l, t, l, b, color, 1);
        self.line(r, t, r, b, color, 1);
    }

    /// Draws the segment from `(x0, y0)` to `(x1, y1)` with a square brush `width` pixels wide
    /// (Bresenham's algorithm on the pixels under the end points, after clipping the segment to
    /// the canvas).
    pub fn line(&mut self, x0: f64, y0: f64, x1: f64, y1: f64, color: [u8; 3], width: u32) {
        let width = width.clamp(1, 64);
        let margin = f64::from(width);
        let Some((x0, y0, x1, y1)) = clip(
            (x0, y0, x1, y1),
            -margin,
            -margin,
            self.width as f64 + margin,
            self.height as f64 + margin,
        ) else {
            return;
        };
        let (mut x, mut y) = (x0.floor() as i64, y0.floor() as i64);
        let (xe, ye) = (x1.floor() as i64, y1.floor() as i64);
        let (dx, dy) = ((xe - x).abs(), -(ye - y).abs());
        let (sx, sy) = (if x < xe { 1 } else { -1 }, if y < ye { 1 } else { -1 });
        let mut err = dx + dy;
        let lo = -(i64::from(width) - 1) / 2;
        let hi = lo + i64::from(width);
        loop {
            for oy in lo..hi {
                for ox in lo..hi {
                    self.blend(x + ox, y + oy, color, 1.0);
                }
            }
            if x == xe && y == ye {
                break;
            }
            let e2 = 2 * err;
            if e2 >= dy {
                err += dy;
                x += sx;
            }
            if e2 <= dx {
                err += dx;
                y += sy;
            }
        }
    }

    /// Fills the disc of radius `r` around `(cx, cy)` (pixels whose centres are within `r`;
    /// at least the pixel under the centre).
    pub fn disc(&mut self, cx: f64, cy: f64, r: f64, color: [u8; 3]) {
        if !(cx.is_finite() && cy.is_finite() && r.is_finite()) {
            return;
        }
        let r = r.clamp(0.0, MAX_CANVAS_SIDE as f64);
        let (i0, i1) = Self::span(cx - r, cx + r + 1.0, self.width);
        let (j0, j1) = Self::span(cy - r, cy + r + 1.0, self.height);
        for y in j0..j1 {
            for x in i0..i1 {
                let (px, py) = (x as f64 + 0.5 - cx, y as f64 + 0.5 - cy);
                if px * px + py * py <= r * r {
                    self.blend(x, y, color, 1.0);
                }
            }
        }
        self.blend(cx.floor() as i64, cy.floor() as i64, color, 1.0);
    }

    /// The image as a [`Frame::Rgb`].
    pub fn into_frame(self) -> Frame {
        Frame::Rgb {
            height: self.height,
            width: self.width,
            data: self.data,
        }
    }
}

/// Liang–Barsky clipping of a segment to `[xmin, xmax] × [ymin, ymax]`; `None` when nothing is
/// left (or a coordinate is not finite).
fn clip(
    (x0, y0, x1, y1): (f64, f64, f64, f64),
    xmin: f64,
    ymin: f64,
    xmax: f64,
    ymax: f64,
) -> Option<(f64, f64, f64, f64)> {
    if ![x0, y0, x1, y1].iter().all(|v| v.is_finite()) {
        return None;
    }
    let (dx, dy) = (x1 - x0, y1 - y0);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [
        (-dx, x0 - xmin),
        (dx, xmax - x0),
        (-dy, y0 - ymin),
        (dy, ymax - y0),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let t = q / p;
            if p < 0.0 {
                t0 = t0.max(t);
            } else {
                t1 = t1.min(t);
            }
        }
    }
    (t0 <= t1).then_some((x0 + t0 * dx, y0 + t0 * dy, x0 + t1 * dx, y0 + t1 * dy))
}

#[cfg(test)]
mod tests {
    use super::*;

    const W: [u8; 3] = [255, 255, 255];
    const K: [u8; 3] = [0, 0, 0];

    fn count(c: &Canvas, color: [u8; 3]) -> usize {
        (0..c.height())
            .flat_map(|y| (0..c.width()).map(move |x| (x, y)))
            .filter(|&(x, y)| c.pixel(x, y) == Some(color))
            .count()
    }

    #[test]
    fn rectangles_cover_pixel_centres_and_tiny_ones_stay_visible() {
        let mut c = Canvas::new(10, 10, W);
        c.fill_rect(2.0, 3.0, 5.0, 4.0, K, 1.0);
        assert_eq!(count(&c, K), 3);
        assert_eq!(c.pixel(2, 3), Some(K));
        assert_eq!(c.pixel(5, 3), Some(W));
        let mut c = Canvas::new(10, 10, W);
        c.fill_rect(7.1, 7.2, 7.3, 7.4, K, 1.0);
        assert_eq!(count(&c, K), 1);
        assert_eq!(c.pixel(7, 7), Some(K));
    }

    #[test]
    fn translucent_fill_blends_with_the_background() {
        let mut c = Canvas::new(2, 2, W);
        c.fill_rect(0.0, 0.0, 2.0, 2.0, [255, 0, 0], 0.5);
        assert_eq!(c.pixel(0, 0), Some([255, 128, 128]));
    }

    #[test]
    fn lines_join_their_end_points_and_clip_without_panicking() {
        let mut c = Canvas::new(20, 10, W);
        c.line(0.5, 0.5, 19.5, 9.5, K, 1);
        assert_eq!(c.pixel(0, 0), Some(K));
        assert_eq!(c.pixel(19, 9), Some(K));
        assert_eq!(count(&c, K), 20);
        // Far outside, huge, infinite or NaN coordinates draw nothing or only the visible part.
        let mut c = Canvas::new(20, 10, W);
        c.line(-1e12, 5.5, 1e12, 5.5, K, 1);
        assert_eq!(count(&c, K), 20);
        c.line(f64::NAN, 0.0, 3.0, 3.0, K, 3);
        c.line(f64::INFINITY, 0.0, 3.0, 3.0, K, 3);
        c.line(100.0, 100.0, 200.0, 200.0, K, 3);
        assert_eq!(count(&c, K), 20);
        let mut c = Canvas::new(20, 10, W);
        c.line(10.5, 5.5, 10.5, 5.5, K, 3);
        assert_eq!(count(&c, K), 9);
    }

    #[test]
    fn outlines_and_discs() {
        let mut c = Canvas::new(10, 10, W);
        c.stroke_rect(1.0, 1.0, 5.0, 5.0, K);
        assert_eq!(count(&c, K), 12);
        assert_eq!(c.pixel(2, 2), Some(W));
        let mut c = Canvas::new(10, 10, W);
        c.disc(5.0, 5.0, 2.0, K);
        assert_eq!(c.pixel(5, 5), Some(K));
        assert_eq!(c.pixel(5, 2), Some(W));
        assert!(count(&c, K) >= 9);
    }

    #[test]
    fn sizes_are_clamped_and_frames_are_row_major() {
        let c = Canvas::new(0, 0, W);
        assert_eq!((c.width(), c.height()), (1, 1));
        let mut c = Canvas::new(3, 2, W);
        c.blend(2, 1, K, 1.0);
        c.blend(-1, 0, K, 1.0);
        c.blend(3, 0, K, 1.0);
        let Frame::Rgb {
            height,
            width,
            data,
        } = c.into_frame()
        else {
            panic!("not rgb");
        };
        assert_eq!((height, width), (2, 3));
        assert_eq!(&data[15..18], &K);
        assert_eq!(data.iter().filter(|&&b| b == 0).count(), 3);
    }
}
