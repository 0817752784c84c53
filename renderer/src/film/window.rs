//! The data window: which pixels of a frame a render produces, given in normalised device
//! coordinates as UsdRender's `dataWindowNDC` gives it (the CLI's `--data-window`). A window
//! inside the unit square crops the frame; one reaching beyond it renders overscan, pixels
//! outside the frame that continue its pixel grid.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `ndc` | (xmin, ymin, xmax, ymax): (0, 0) the frame's bottom-left corner, (1, 1) its top-right | frame widths / heights | (0, 0, 1, 1) |
//!
//! A pixel is in the window when its centre is (UsdRender's rule): x_min ≤ (i + ½)/W < x_max
//! for column i, and y_min < 1 − (j + ½)/H ≤ y_max for row j (rows counted from the top), so
//! that two windows meeting at an edge share no pixel.

use crate::error::{Error, Result};

/// Largest overscan on each side, in frames (a window may reach from −4 to 5).
pub const MAX_OVERSCAN_FRAMES: f64 = 4.0;

/// A data window in pixels of a `width` × `height` frame: columns `x0..x1`, rows `y0..y1`
/// (row 0 at the top); negative or beyond the frame where it overscans.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PixelWindow {
    /// First column.
    pub x0: i64,
    /// First row.
    pub y0: i64,
    /// One past the last column.
    pub x1: i64,
    /// One past the last row.
    pub y1: i64,
}

impl PixelWindow {
    /// The pixels of the `width` × `height` frame whose centres lie in `ndc` (`field` names the
    /// setting in errors). Errors: a non-finite or inverted window, one holding no pixel centre,
    /// one reaching more than [`MAX_OVERSCAN_FRAMES`] beyond the frame.
    pub fn from_ndc(ndc: [f64; 4], width: u32, height: u32, field: &str) -> Result<Self> {
        let [x_min, y_min, x_max, y_max] = ndc;
        let bad = |m: String| Err(Error::settings(field, m));
        if !ndc.iter().all(|v| v.is_finite()) {
            return bad(format!("{ndc:?} must be four finite numbers (xmin, ymin, xmax, ymax)"));
        }
        if !(x_min < x_max && y_min < y_max) {
            return bad(format!("{ndc:?} is empty: xmin < xmax and ymin < ymax are needed"));
        }
        let (lo, hi) = (-MAX_OVERSCAN_FRAMES, 1.0 + MAX_OVERSCAN_FRAMES);
        if ndc.iter().any(|&v| !(lo..=hi).contains(&v)) {
            return bad(format!("{ndc:?} reaches more than {MAX_OVERSCAN_FRAMES} frames beyond the frame"));
        }
        // 1. Columns: centres (i + ½)/W in [x_min, x_max).
        let (w, h) = (width as f64, height as f64);
        let x0 = (x_min * w - 0.5).ceil() as i64;
        let x1 = (x_max * w - 0.5).ceil() as i64;
        // 2. Rows: centres 1 − (j + ½)/H in (y_min, y_max], i.e. j in [(1 − y_max)·H − ½, (1 − y_min)·H − ½).
        let y0 = ((1.0 - y_max) * h - 0.5).ceil() as i64;
        let y1 = ((1.0 - y_min) * h - 0.5).ceil() as i64;
        if !(x0 < x1 && y0 < y1) {
            return bad(format!("{ndc:?} holds no pixel centre of the {width}x{height} frame"));
        }
        Ok(PixelWindow { x0, y0, x1, y1 })
    }

    /// The whole `width` × `height` frame.
    pub fn full(width: u32, height: u32) -> Self {
        PixelWindow { x0: 0, y0: 0, x1: width as i64, y1: height as i64 }
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        (self.x1 - self.x0) as u32
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        (self.y1 - self.y0) as u32
    }

    /// The smallest pixel rectangle holding both this window and the `width` × `height` frame:
    /// the frame a render makes (the window inside it is then a crop).
    pub fn union_with_frame(&self, width: u32, height: u32) -> PixelWindow {
        PixelWindow {
            x0: self.x0.min(0),
            y0: self.y0.min(0),
            x1: self.x1.max(width as i64),
            y1: self.y1.max(height as i64),
        }
    }

    /// Whether the window lies within the `width` × `height` frame (no overscan).
    pub fn inside(&self, width: u32, height: u32) -> bool {
        self.x0 >= 0 && self.y0 >= 0 && self.x1 <= width as i64 && self.y1 <= height as i64
    }

    /// This window as a crop `[x0, y0, x1, y1)` of the frame `outer` (which holds it).
    pub fn crop_in(&self, outer: &PixelWindow) -> [u32; 4] {
        [
            (self.x0 - outer.x0) as u32,
            (self.y0 - outer.y0) as u32,
            (self.x1 - outer.x0) as u32,
            (self.y1 - outer.y0) as u32,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_square_is_the_frame() {
        for (w, h) in [(1, 1), (4, 3), (640, 480), (17, 5)] {
            assert_eq!(PixelWindow::from_ndc([0.0, 0.0, 1.0, 1.0], w, h, "t").unwrap(), PixelWindow::full(w, h));
        }
    }

    #[test]
    fn pixel_centres_decide_and_neighbours_share_nothing() {
        // 8 columns: centres 1/16, 3/16, ...; [0.25, 0.5) holds columns 2 and 3 (centres 5/16, 7/16).
        let a = PixelWindow::from_ndc([0.25, 0.0, 0.5, 1.0], 8, 4, "t").unwrap();
        assert_eq!((a.x0, a.x1), (2, 4));
        // the bottom half (y up) is rows 2 and 3 (row 0 at the top)
        let b = PixelWindow::from_ndc([0.0, 0.0, 1.0, 0.5], 8, 4, "t").unwrap();
        assert_eq!((b.y0, b.y1), (2, 4));
        let t = PixelWindow::from_ndc([0.0, 0.5, 1.0, 1.0], 8, 4, "t").unwrap();
        assert_eq!((t.y0, t.y1), (0, 2));
        // edges through pixel centres: 5 columns, centres 0.1, 0.3, 0.5, 0.7, 0.9
        let l = PixelWindow::from_ndc([0.0, 0.0, 0.5, 1.0], 5, 5, "t").unwrap();
        let r = PixelWindow::from_ndc([0.5, 0.0, 1.0, 1.0], 5, 5, "t").unwrap();
        assert_eq!((l.x0, l.x1, r.x0, r.x1), (0, 2, 2, 5));
        let lo = PixelWindow::from_ndc([0.0, 0.0, 1.0, 0.5], 5, 5, "t").unwrap();
        let hi = PixelWindow::from_ndc([0.0, 0.5, 1.0, 1.0], 5, 5, "t").unwrap();
        assert_eq!((hi.y0, hi.y1, lo.y0, lo.y1), (0, 2, 2, 5));
    }

    #[test]
    fn overscan_reaches_outside_the_frame() {
        let o = PixelWindow::from_ndc([-0.25, -0.5, 1.25, 1.0], 40, 20, "t").unwrap();
        assert_eq!(o, PixelWindow { x0: -10, y0: 0, x1: 50, y1: 30 });
        assert!(!o.inside(40, 20));
        let u = o.union_with_frame(40, 20);
        assert_eq!(u, o);
        assert_eq!(PixelWindow::full(40, 20).crop_in(&u), [10, 0, 50, 20]);
        let c = PixelWindow::from_ndc([0.5, 0.5, 0.75, 0.75], 40, 20, "t").unwrap();
        assert!(c.inside(40, 20));
        assert_eq!(c.union_with_frame(40, 20), PixelWindow::full(40, 20));
    }

    #[test]
    fn bad_windows_name_the_field() {
        for ndc in [
            [0.5, 0.0, 0.5, 1.0],
            [0.0, 1.0, 1.0, 0.0],
            [f64::NAN, 0.0, 1.0, 1.0],
            [0.0, 0.0, 1.0, f64::INFINITY],
            [0.0, 0.0, 9.0, 1.0],
            [0.3, 0.0, 0.31, 1.0],
        ] {
            let e = PixelWindow::from_ndc(ndc, 10, 10, "dataWindowNDC").unwrap_err().to_string();
            assert!(e.contains("dataWindowNDC"), "{e}");
        }
    }
}
