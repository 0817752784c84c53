//! `petzval lens draw`: an SVG cross-section (x–z meridian) with elements, the stop and a fan of
//! traced rays for three field positions (centre, half and full image height).

use super::lens::{Lens, Ray, TraceDirection};
use super::pupil::ExitPupilBounds;
use glam::DVec3;
use std::fmt::Write;

/// Largest image height drawn (half the 36×24 mm diagonal).
const MAX_IMAGE_HEIGHT_MM: f64 = 21.63;

/// Renders the cross-section of `lens` with its film plane at `film_z_mm`.
pub fn section_svg(lens: &Lens, film_z_mm: f64) -> String {
    let surfaces = lens.surfaces();
    let max_sd = surfaces.iter().map(|s| s.housing_semi_diameter_mm.max(s.semi_diameter_mm)).fold(0.0, f64::max);
    // 1. Film heights: up to the largest radius that still passes light.
    let bounds = ExitPupilBounds::compute_with(lens, film_z_mm, 0.0, MAX_IMAGE_HEIGHT_MM, 32, 4, 32);
    let h_max = (0..bounds.boxes.len())
        .rev()
        .find(|&k| !bounds.boxes[k].is_empty())
        .map(|k| MAX_IMAGE_HEIGHT_MM * k as f64 / bounds.boxes.len() as f64)
        .unwrap_or(0.0);
    let lead = 0.35 * (film_z_mm.max(lens.last_vertex_z_mm())).max(4.0 * max_sd);
    let (z_min, z_max) = (-lead, film_z_mm + 2.0);
    let x_ext = max_sd.max(h_max) * 1.15;
    let width = 1000.0;
    let scale = width / (z_max - z_min);
    let height = 2.0 * x_ext * scale + 60.0;
    let to_svg = |z: f64, x: f64| ((z - z_min) * scale, height * 0.5 - 10.0 - x * scale);
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0}" height="{height:.0}" viewBox="0 0 {width:.0} {height:.0}"><rect width="100%" height="100%" fill="white"/>"#
    );
    let _ = writeln!(
        svg,
        r#"<text x="8" y="{:.0}" font-family="sans-serif" font-size="14">{} — f = {:.2} mm, f/{:.2}</text>"#,
        height - 8.0,
        xml(lens.name()),
        lens.paraxial().efl_mm,
        lens.paraxial().f_number
    );
    // 2. Optical axis and film plane.
    let (ax0, ay) = to_svg(z_min, 0.0);
    let (ax1, _) = to_svg(z_max, 0.0);
    let _ = writeln!(
        svg,
        r##"<line x1="{ax0:.2}" y1="{ay:.2}" x2="{ax1:.2}" y2="{ay:.2}" stroke="#999" stroke-dasharray="6 4"/>"##
    );
    let (fx, fy0) = to_svg(film_z_mm, x_ext);
    let (_, fy1) = to_svg(film_z_mm, -x_ext);
    let _ = writeln!(
        svg,
        r##"<line x1="{fx:.2}" y1="{fy0:.2}" x2="{fx:.2}" y2="{fy1:.2}" stroke="#333" stroke-width="2"/>"##
    );
    // 3. Elements: glass between surface i and i+1.
    let profile = |i: usize, r: f64| -> Vec<(f64, f64)> {
        let s = &surfaces[i];
        (0..=40)
            .map(|k| {
                let x = -r + 2.0 * r * k as f64 / 40.0;
                (s.z_mm + s.shape.sag(x, 0.0).unwrap_or(0.0), x)
            })
            .collect()
    };
    for i in 0..surfaces.len() {
        let s = &surfaces[i];
        if s.is_stop {
            let (x, y0) = to_svg(s.z_mm, s.housing_semi_diameter_mm.max(lens.stop_semi_diameter_mm() * 1.3));
            let (_, y1) = to_svg(s.z_mm, lens.stop_semi_diameter_mm());
            let (_, y2) = to_svg(s.z_mm, -lens.stop_semi_diameter_mm());
            let (_, y3) = to_svg(s.z_mm, -s.housing_semi_diameter_mm.max(lens.stop_semi_diameter_mm() * 1.3));
            let _ = writeln!(
                svg,
                r#"<line x1="{x:.2}" y1="{y0:.2}" x2="{x:.2}" y2="{y1:.2}" stroke="black" stroke-width="3"/><line x1="{x:.2}" y1="{y2:.2}" x2="{x:.2}" y2="{y3:.2}" stroke="black" stroke-width="3"/>"#
            );
            continue;
        }
        if s.material_after == super::glass::Material::Air || i + 1 >= surfaces.len() {
            continue;
        }
        let r = s.semi_diameter_mm.max(surfaces[i + 1].semi_diameter_mm);
        let mut pts = profile(i, s.semi_diameter_mm);
        let mut back = profile(i + 1, surfaces[i + 1].semi_diameter_mm);
        back.reverse();
        // flat edges out to the larger radius
        let front_edge = pts.last().copied().unwrap_or_default();
        pts.push((front_edge.0, r));
        let back_edge = back.first().copied().unwrap_or_default();
        pts.push((back_edge.0, r));
        pts.extend(back.iter().copied());
        let last = pts.last().copied().unwrap_or_default();
        pts.push((last.0, -r));
        pts.push((pts[0].0, -r));
        let d: Vec<String> = pts
            .iter()
            .map(|&(z, x)| {
                let (a, b) = to_svg(z, x);
                format!("{a:.2},{b:.2}")
            })
            .collect();
        let _ = writeln!(
            svg,
            r##"<polygon points="{}" fill="#cfe3f7" stroke="#2a5d8f" stroke-width="1.2"/>"##,
            d.join(" ")
        );
    }
    // 4. Ray fans from three film heights, traced film → scene through the exit-pupil bounds.
    let colours = ["#d62728", "#2ca02c", "#1f77b4"];
    for (f, colour) in [0.0f64, 0.5, 1.0].iter().zip(colours) {
        let h = -f * h_max; // film x < 0 images the +x side of the scene
        let b = bounds.box_for_radius(h.abs());
        if b.is_empty() {
            continue;
        }
        let film = DVec3::new(h, 0.0, film_z_mm);
        for k in 0..=10 {
            let mut x = b.min.x + (b.max.x - b.min.x) * k as f64 / 10.0;
            if h < 0.0 {
                x = -x; // box is for a film point on +x; mirror
            }
            let target = DVec3::new(x, 0.0, lens.last_vertex_z_mm());
            let (pts, result) = lens.trace_path(
                &Ray::new(film, target - film),
                lens.primary_wavelength_nm(),
                TraceDirection::FilmToScene,
            );
            let Ok(out) = result else { continue };
            let t = (out.ray.origin.z - z_min) / (-out.ray.direction.z).max(0.2);
            let end = out.ray.origin + out.ray.direction * t.min(3.0 * lead);
            let d: Vec<String> = pts
                .iter()
                .chain(std::iter::once(&end))
                .map(|p| {
                    let (a, b) = to_svg(p.z, p.x);
                    format!("{a:.2},{b:.2}")
                })
                .collect();
            let _ = writeln!(
                svg,
                r#"<polyline points="{}" fill="none" stroke="{colour}" stroke-width="0.8" opacity="0.85"/>"#,
                d.join(" ")
            );
        }
    }
    svg.push_str("</svg>\n");
    svg
}

fn xml(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}
