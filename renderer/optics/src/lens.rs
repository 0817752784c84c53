//! A lens system built from a validated prescription, and exact sequential ray tracing (f64) in
//! both directions.
//!
//! Frame: millimetres, z along the optical axis from the first surface's vertex, positive
//! towards the film; x to the right and y up as seen from the film looking at the scene.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `stop_semi_diameter_mm` | f64, current stop opening (circumradius) | mm | file's `stop_semi_diameter_mm`, else widest |
//! | `wavelength_nm` (per trace) | f64 | nm | primary wavelength |

use super::aperture::{Aperture, ApertureMask, ApertureShape, PreparedAperture};
use super::glass::{Material, WAVELENGTH_D_NM};
use super::paraxial::{self, ParaxialData};
use super::prescription::{self, ApertureShapeSpec, Prescription, SourceMap, DEFAULT_WAVELENGTHS_NM};
use super::surface::{refract, Shape};
use crate::error::{Error, Result};
use glam::{DMat3, DVec2, DVec3};
use std::path::Path;
use std::sync::Arc;

/// A ray in the lens frame (mm); `direction` is a unit vector.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    /// Origin.
    pub origin: DVec3,
    /// Unit direction.
    pub direction: DVec3,
}

impl Ray {
    /// A ray; the direction is normalised.
    pub fn new(origin: DVec3, direction: DVec3) -> Ray {
        Ray { origin, direction: direction.normalize() }
    }
}

/// Which way a ray travels through the lens.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TraceDirection {
    /// From the scene (front) to the film (back).
    SceneToFilm,
    /// From the film (back) to the scene (front): rendering.
    FilmToScene,
}

/// Why a ray did not make it through.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Absorbed {
    /// Missed surface `i` (no intersection, or hit behind the ray).
    Missed(usize),
    /// Hit surface `i` outside its semi-diameter.
    Clipped(usize),
    /// Total internal reflection at surface `i`.
    TotalInternalReflection(usize),
    /// Blocked by the stop opening.
    Stop,
}

/// What came out of the lens.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Traced {
    /// The outgoing ray, starting on the last surface it crossed.
    pub ray: Ray,
    /// Stop transmission (1 inside a hard-edged opening; grey levels for a mask).
    pub transmission: f64,
    /// Where the ray crossed the stop plane (x, y).
    pub stop_point: DVec2,
}

/// Whether the stop opening clips rays.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopMode {
    /// Apply the current opening and shape.
    Apply,
    /// Only the stop's housing clips (for baking tables with the stop open).
    Open,
}

/// One surface of a built lens.
#[derive(Debug, Clone)]
pub struct LensSurface {
    /// Vertex position on the axis.
    pub z_mm: f64,
    /// Distance to the next surface.
    pub thickness_mm: f64,
    /// Geometry.
    pub shape: Shape,
    /// Clear semi-diameter (the stop's: its widest opening).
    pub semi_diameter_mm: f64,
    /// Medium after the surface.
    pub material_after: Material,
    /// This is the aperture stop.
    pub is_stop: bool,
    /// Mechanical radius (stop housing; equals the semi-diameter otherwise).
    pub housing_semi_diameter_mm: f64,
    /// Rigid misplacement of the element this surface belongs to (None: on the axis).
    pub placement: Option<Placement>,
}

/// Where a misaligned element sits: a point `p` of the aligned element is at
/// `pivot + offset + rotation · (p − pivot)` in the lens frame. Shared by every surface of the
/// element.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// The pivot: the element's front vertex on the axis (lens frame).
    pub pivot: DVec3,
    /// Displacement of the pivot (decentre x, y; z in reversed lenses).
    pub offset: DVec3,
    /// Rotation about the pivot (aligned element → lens frame).
    pub rotation: DMat3,
}

impl Placement {
    /// The placement of an element with front vertex at `vertex_z_mm`, decentred by
    /// (`dx`, `dy`) mm and tilted by `tilt_x_deg` then `tilt_y_deg` (right-handed rotations).
    pub fn from_misalignment(vertex_z_mm: f64, dx: f64, dy: f64, tilt_x_deg: f64, tilt_y_deg: f64) -> Placement {
        let rotation =
            DMat3::from_rotation_y(tilt_y_deg.to_radians()) * DMat3::from_rotation_x(tilt_x_deg.to_radians());
        Placement { pivot: DVec3::new(0.0, 0.0, vertex_z_mm), offset: DVec3::new(dx, dy, 0.0), rotation }
    }

    /// A lens-frame point in the aligned element's frame.
    #[inline]
    pub(crate) fn point_to_element(&self, p: DVec3) -> DVec3 {
        self.rotation.transpose() * (p - self.pivot - self.offset) + self.pivot
    }

    /// An aligned-element point in the lens frame.
    #[inline]
    pub(crate) fn point_to_lens(&self, p: DVec3) -> DVec3 {
        self.rotation * (p - self.pivot) + self.pivot + self.offset
    }

    /// The same placement in the lens mirrored about z (`z → length − z`), as [`Lens::reversed`]
    /// sees it; its pivot stays the same physical point.
    fn mirrored(&self, length_mm: f64) -> Placement {
        let m = DMat3::from_diagonal(DVec3::new(1.0, 1.0, -1.0));
        Placement {
            pivot: DVec3::new(self.pivot.x, self.pivot.y, length_mm - self.pivot.z),
            offset: m * self.offset,
            rotation: m * self.rotation * m,
        }
    }
}

/// A lens system ready to trace. Immutable; [`Lens::with_stop_semi_diameter`] and
/// [`Lens::stopped_down`] return new lenses, and [`Lens::rebuild`] is the one entry point that
/// rebuilds from an edited prescription (used by fitting).
#[derive(Debug, Clone)]
pub struct Lens {
    prescription: Prescription,
    source_label: String,
    surfaces: Vec<LensSurface>,
    stop_index: usize,
    stop_semi_diameter_mm: f64,
    aperture: PreparedAperture,
    primary_wavelength_nm: f64,
    wavelengths_nm: Vec<f64>,
    /// Index after each surface at the primary wavelength.
    primary_index_after: Vec<f64>,
    /// First-order data at the primary wavelength, for the current stop opening: set by
    /// [`Lens::analysed`], which every constructor and every copy-with-change ends with.
    paraxial: ParaxialData,
    rotationally_symmetric: bool,
}

impl Lens {
    /// Builds from a prescription. `map` names the file in errors; `base_dir` resolves a mask
    /// image path.
    pub fn new(p: Prescription, map: &SourceMap, base_dir: Option<&Path>) -> Result<Lens> {
        // 1. Field checks and material look-up.
        let resolved = prescription::resolve(&p, map)?;
        // 2. Surfaces with absolute positions.
        let mut z = 0.0;
        let mut surfaces = Vec::with_capacity(resolved.len());
        for r in &resolved {
            let s = &r.spec;
            let shape = Shape {
                curvature_per_mm: if s.radius_mm == 0.0 { 0.0 } else { 1.0 / s.radius_mm },
                conic: s.conic,
                a2: s.aspheric_r2,
                aspheric: s.aspheric.clone(),
                aspheric_odd: s.aspheric_odd.clone(),
                cylinder: s.cylinder,
            };
            surfaces.push(LensSurface {
                z_mm: z,
                thickness_mm: s.thickness_mm,
                shape,
                semi_diameter_mm: s.semi_diameter_mm,
                material_after: r.material_after.clone(),
                is_stop: s.stop,
                housing_semi_diameter_mm: s.housing_semi_diameter_mm.unwrap_or(s.semi_diameter_mm),
                placement: None,
            });
            z += s.thickness_mm;
        }
        // Misaligned elements: the placement of the element's first surface moves every surface
        // up to the one followed by air (checked in `resolve`: it starts an element).
        for (i, r) in resolved.iter().enumerate() {
            let s = &r.spec;
            if s.is_misaligned() {
                let placement = Placement::from_misalignment(
                    surfaces[i].z_mm,
                    s.decenter_x_mm,
                    s.decenter_y_mm,
                    s.tilt_x_deg,
                    s.tilt_y_deg,
                );
                for surface in surfaces[i..].iter_mut() {
                    surface.placement = Some(placement);
                    if surface.material_after == Material::Air {
                        break;
                    }
                }
            }
        }
        check_geometry(&surfaces, map)?;
        let stop_index = surfaces.iter().position(|s| s.is_stop).unwrap_or(0);
        // 3. Aperture shape.
        let a = &p.aperture;
        let shape = match a.shape {
            ApertureShapeSpec::Circle => ApertureShape::Circle,
            ApertureShapeSpec::Blades => {
                ApertureShape::Blades { count: a.blades.unwrap_or(6), curvature: a.blade_curvature }
            }
            ApertureShapeSpec::Image => {
                let rel = a.image.clone().unwrap_or_default();
                let path = match base_dir {
                    Some(d) => d.join(&rel),
                    None => rel.into(),
                };
                // named as the lens file's field, with the path it resolved to
                let mask = ApertureMask::load(&path).map_err(|e| match e {
                    Error::ApertureImage { path, message } => {
                        map.aperture_error("image", format!("{}: {message}", path.display()))
                    }
                    other => other,
                })?;
                ApertureShape::Mask(Arc::new(mask))
            }
        };
        let aperture =
            Aperture { shape, rotation_rad: a.rotation_deg.to_radians(), anamorphic_ratio: a.anamorphic_ratio };
        let primary = p.lens.primary_wavelength_nm.unwrap_or(WAVELENGTH_D_NM);
        let wavelengths = p.lens.wavelengths_nm.clone().unwrap_or_else(|| DEFAULT_WAVELENGTHS_NM.to_vec());
        let primary_index_after = surfaces.iter().map(|s| s.material_after.index(primary)).collect();
        let rotationally_symmetric =
            surfaces.iter().all(|s| s.shape.is_rotationally_symmetric() && s.placement.is_none());
        let stop_open = p.lens.stop_semi_diameter_mm.unwrap_or(surfaces[stop_index].semi_diameter_mm);
        let lens = Lens {
            prescription: p,
            source_label: map.file.clone(),
            surfaces,
            stop_index,
            stop_semi_diameter_mm: stop_open,
            aperture: PreparedAperture::new(aperture),
            primary_wavelength_nm: primary,
            wavelengths_nm: wavelengths,
            primary_index_after,
            paraxial: ParaxialData::default(),
            rotationally_symmetric,
        };
        // 4. Precompute first-order data.
        Ok(lens.analysed())
    }

    /// Whether the lens forms an image (it has optical power in some meridian): an error
    /// naming the lens when it does not. A plate or an afocal system traces fine, but nothing
    /// can be focused, rendered or tabulated through it.
    pub fn check_forms_image(&self) -> Result<()> {
        let has_power = |f: f64| f.is_finite() && f.abs() < 1e7;
        if has_power(self.paraxial.efl_mm) || has_power(self.paraxial.efl_x_mm) {
            return Ok(());
        }
        Err(Error::Optics(format!(
            "{}: the lens has no optical power (its focal length is infinite): it forms no image",
            self.source_label
        )))
    }

    /// This lens with its first-order data computed for its current surfaces and stop: the
    /// last step of every constructor and copy-with-change, so no `Lens` carries stale
    /// paraxial data.
    fn analysed(mut self) -> Lens {
        self.paraxial = paraxial::analyse(&self, self.primary_wavelength_nm);
        self
    }

    /// The same lens seen from the other side: surfaces in reverse order, mirrored in z
    /// (radii and aspheric terms change sign), each medium moved to the other side of its
    /// surface, the stop kept at its surface and opening. A point (x, y, z) of this lens is the
    /// point (x, y, L − z) of the reversed one, L = [`Lens::last_vertex_z_mm`]; so tracing
    /// scene → film here is tracing film → scene there (used for the scene → film LRTF). The
    /// reversed lens's last thickness is its paraxial back focal length. Its name gains
    /// " (reversed)", so tables baked for it are never mistaken for the lens's own.
    pub fn reversed(&self) -> Result<Lens> {
        let p = &self.prescription;
        let n = p.surfaces.len();
        let air = prescription::MaterialSpec::Name("air".into());
        let mut q = p.clone();
        q.lens.name = format!("{} (reversed)", p.lens.name);
        q.lens.focal_length_mm = None;
        // The stop shape is applied below (an image stop's file was resolved at load).
        q.aperture.shape = ApertureShapeSpec::Circle;
        q.aperture.image = None;
        q.surfaces = (0..n)
            .map(|i| {
                let old = &p.surfaces[n - 1 - i];
                let mut s = old.clone();
                s.radius_mm = -old.radius_mm;
                s.aspheric_r2 = -old.aspheric_r2;
                s.aspheric = old.aspheric.iter().map(|a| -a).collect();
                s.aspheric_odd = old.aspheric_odd.iter().map(|b| -b).collect();
                s.material = if i + 1 < n { p.surfaces[n - 2 - i].material.clone() } else { air.clone() };
                s.thickness_mm = if i + 1 < n { p.surfaces[n - 2 - i].thickness_mm } else { 0.0 };
                // placements are mirrored onto the built surfaces below
                (s.decenter_x_mm, s.decenter_y_mm, s.tilt_x_deg, s.tilt_y_deg) = (0.0, 0.0, 0.0, 0.0);
                s
            })
            .collect();
        let map = SourceMap::new(format!("{} (reversed)", self.source_label), vec![]);
        let mut lens = Lens::new(q.clone(), &map, None)?;
        // The image side: at the paraxial back focus of the reversed lens.
        let bfl = lens.paraxial().bfl_mm;
        if bfl.is_finite() && bfl > 0.0 {
            if let Some(last) = q.surfaces.last_mut() {
                last.thickness_mm = bfl;
            }
            lens = Lens::new(q, &map, None)?;
        }
        // Misaligned elements: the same physical placement, seen from the other side.
        let length = self.last_vertex_z_mm();
        if self.surfaces.iter().any(|s| s.placement.is_some()) {
            for (i, surface) in lens.surfaces.iter_mut().enumerate() {
                surface.placement = self.surfaces[n - 1 - i].placement.map(|pl| pl.mirrored(length));
            }
            lens.rotationally_symmetric = false;
        }
        lens = lens.with_aperture(self.aperture().clone());
        lens.with_stop_semi_diameter(self.stop_semi_diameter_mm.min(lens.max_stop_semi_diameter_mm()))
    }

    /// Parses and builds a lens from our TOML text.
    pub fn from_toml(text: &str, file: &str, base_dir: Option<&Path>) -> Result<Lens> {
        let (p, map) = prescription::parse_toml(text, file)?;
        Lens::new(p, &map, base_dir)
    }

    /// Rebuilds from an edited prescription, keeping the current stop opening when it still fits.
    pub fn rebuild(&self, p: Prescription) -> Result<Lens> {
        let map = SourceMap::new(self.source_label.clone(), vec![]);
        let lens = Lens::new(p, &map, None)?;
        let r = self.stop_semi_diameter_mm.min(lens.surfaces[lens.stop_index].semi_diameter_mm);
        lens.with_stop_semi_diameter(r)
    }

    /// The prescription this lens was built from.
    pub fn prescription(&self) -> &Prescription {
        &self.prescription
    }
    /// Lens name.
    pub fn name(&self) -> &str {
        &self.prescription.lens.name
    }
    /// Where the lens was loaded from (file path or `library:NAME`).
    pub fn source_label(&self) -> &str {
        &self.source_label
    }
    /// Surfaces, front to back.
    pub fn surfaces(&self) -> &[LensSurface] {
        &self.surfaces
    }
    /// Index of the aperture stop.
    pub fn stop_index(&self) -> usize {
        self.stop_index
    }
    /// Current stop opening (circumradius).
    pub fn stop_semi_diameter_mm(&self) -> f64 {
        self.stop_semi_diameter_mm
    }
    /// Widest stop opening.
    pub fn max_stop_semi_diameter_mm(&self) -> f64 {
        self.surfaces[self.stop_index].semi_diameter_mm
    }
    /// The stop's shape.
    pub fn aperture(&self) -> &Aperture {
        self.aperture.aperture()
    }
    /// Primary wavelength.
    pub fn primary_wavelength_nm(&self) -> f64 {
        self.primary_wavelength_nm
    }
    /// Design wavelengths.
    pub fn wavelengths_nm(&self) -> &[f64] {
        &self.wavelengths_nm
    }
    /// First-order data at the primary wavelength and current stop.
    pub fn paraxial(&self) -> &ParaxialData {
        &self.paraxial
    }
    /// Whether every surface is rotationally symmetric (no cylinders).
    pub fn is_rotationally_symmetric(&self) -> bool {
        self.rotationally_symmetric
    }
    /// Whether any glass disperses.
    pub fn has_dispersion(&self) -> bool {
        self.surfaces.iter().any(|s| s.material_after.is_dispersive())
    }
    /// z of the last surface's vertex.
    pub fn last_vertex_z_mm(&self) -> f64 {
        self.surfaces.last().map(|s| s.z_mm).unwrap_or(0.0)
    }
    /// Distance from the last vertex to the design image plane (the file's last thickness, or the
    /// paraxial back focal length when that is 0).
    pub fn design_back_focus_mm(&self) -> f64 {
        let t = self.surfaces.last().map(|s| s.thickness_mm).unwrap_or(0.0);
        if t > 0.0 {
            t
        } else {
            self.paraxial().bfl_mm
        }
    }
    /// Largest clear semi-diameter of the last (film-side) surface.
    pub fn rear_semi_diameter_mm(&self) -> f64 {
        self.surfaces.last().map(|s| s.semi_diameter_mm).unwrap_or(0.0)
    }

    /// Index of the medium before surface `i` (scene side).
    #[inline]
    pub fn index_before(&self, i: usize, wavelength_nm: f64) -> f64 {
        if i == 0 {
            1.0
        } else {
            self.index_after(i - 1, wavelength_nm)
        }
    }

    /// Index of the medium after surface `i` (film side).
    #[inline]
    pub fn index_after(&self, i: usize, wavelength_nm: f64) -> f64 {
        if wavelength_nm == self.primary_wavelength_nm {
            self.primary_index_after[i]
        } else {
            self.surfaces[i].material_after.index(wavelength_nm)
        }
    }

    /// A copy with the stop opened or closed to `semi_diameter_mm`.
    pub fn with_stop_semi_diameter(&self, semi_diameter_mm: f64) -> Result<Lens> {
        let max = self.max_stop_semi_diameter_mm();
        if !(semi_diameter_mm.is_finite() && semi_diameter_mm > 0.0 && semi_diameter_mm <= max * (1.0 + 1e-12)) {
            return Err(Error::Optics(format!(
                "stop semi-diameter {semi_diameter_mm} mm is outside (0, {max}] mm for lens '{}'",
                self.name()
            )));
        }
        let mut lens = self.clone();
        lens.stop_semi_diameter_mm = semi_diameter_mm.min(max);
        Ok(lens.analysed())
    }

    /// A copy whose stop is the circle containing the current opening (for conservative
    /// sampling bounds of bladed, masked or anamorphic openings); the housing still clips.
    pub fn with_circumscribed_circular_stop(&self) -> Lens {
        let mut lens = self.clone();
        lens.stop_semi_diameter_mm = self.stop_semi_diameter_mm * self.aperture().bounding_radius_factor();
        lens.aperture = PreparedAperture::new(Aperture::default());
        // The pupils grow with the stop (the paraxial data was the smaller opening's).
        lens.analysed()
    }

    /// A copy stopped to f-number `f_number` (object at infinity). Errors when the lens cannot
    /// open that wide.
    pub fn stopped_down(&self, f_number: f64) -> Result<Lens> {
        let r = paraxial::stop_radius_for_f_number(self, f_number)?;
        let max = self.max_stop_semi_diameter_mm();
        if r > max * (1.0 + 1e-9) {
            let widest = f_number * r / max;
            return Err(Error::Optics(format!(
                "lens '{}' cannot open to f/{f_number}: its widest aperture is f/{widest:.3}",
                self.name()
            )));
        }
        self.with_stop_semi_diameter(r.min(max))
    }

    /// A copy stopped to `f_number`, or fully open when the lens cannot open that wide (as a
    /// camera body does); the flag says it was opened fully instead.
    pub fn stopped_down_or_open(&self, f_number: f64) -> Result<(Lens, bool)> {
        let r = paraxial::stop_radius_for_f_number(self, f_number)?;
        let max = self.max_stop_semi_diameter_mm();
        if r > max * (1.0 + 1e-9) {
            return Ok((self.with_stop_semi_diameter(max)?, true));
        }
        Ok((self.with_stop_semi_diameter(r)?, false))
    }

    /// A copy with a different stop shape.
    pub fn with_aperture(&self, aperture: Aperture) -> Lens {
        let mut lens = self.clone();
        lens.aperture = PreparedAperture::new(aperture);
        lens
    }

    /// Traces a ray through every surface. `None` when absorbed.
    #[inline]
    pub fn trace(&self, ray: &Ray, wavelength_nm: f64, direction: TraceDirection) -> Option<Traced> {
        self.trace_detailed(ray, wavelength_nm, direction, StopMode::Apply).ok()
    }

    /// Traces a ray through every surface, saying where it was absorbed.
    pub fn trace_detailed(
        &self,
        ray: &Ray,
        wavelength_nm: f64,
        direction: TraceDirection,
        stop: StopMode,
    ) -> Result<Traced, Absorbed> {
        self.trace_visiting(ray, wavelength_nm, direction, stop, |_| {})
    }

    /// Traces a ray and also returns every surface hit point (for drawing).
    pub fn trace_path(
        &self,
        ray: &Ray,
        wavelength_nm: f64,
        direction: TraceDirection,
    ) -> (Vec<DVec3>, Result<Traced, Absorbed>) {
        let mut points = vec![ray.origin];
        let r = self.trace_visiting(ray, wavelength_nm, direction, StopMode::Apply, |p| points.push(p));
        (points, r)
    }

    /// The trace kernel: `visit` sees each surface hit point (lens frame).
    #[inline]
    fn trace_visiting<F: FnMut(DVec3)>(
        &self,
        ray: &Ray,
        wavelength_nm: f64,
        direction: TraceDirection,
        stop: StopMode,
        mut visit: F,
    ) -> Result<Traced, Absorbed> {
        self.trace_kernel::<false, _>(ray, wavelength_nm, direction, stop, &[], |_, p, _| visit(p)).map(|(t, _)| t)
    }

    /// Traces a ray through every surface without stopping at any rim (soft clipping): the
    /// result carries the smallest weighted clearance `min_i weights[i] · c_i`, where `c_i` is
    /// how far (mm) inside surface `i`'s rim the ray crossed (negative outside; at the stop, the
    /// smaller of its housing's and its opening's clearance). `weights` has one entry per
    /// surface (front to back); a mask stop's grey level stays in the transmission. Only a
    /// missed surface or total internal reflection ends the trace. The clearance is a
    /// continuous function of the ray, so it can weight a ray smoothly across a rim.
    pub fn trace_soft(
        &self,
        ray: &Ray,
        wavelength_nm: f64,
        direction: TraceDirection,
        weights: &[f64],
    ) -> Result<(Traced, f64), Absorbed> {
        debug_assert_eq!(weights.len(), self.surfaces.len());
        self.trace_kernel::<true, _>(ray, wavelength_nm, direction, StopMode::Apply, weights, |_, _, _| {})
    }

    /// Traces a ray without stopping at any rim and returns where it crossed each surface, in
    /// that surface's own frame (x, y), front to back whatever the direction.
    pub fn trace_unclipped_hits(
        &self,
        ray: &Ray,
        wavelength_nm: f64,
        direction: TraceDirection,
    ) -> Result<Vec<DVec2>, Absorbed> {
        let mut hits = vec![DVec2::ZERO; self.surfaces.len()];
        let ones = vec![1.0; self.surfaces.len()];
        self.trace_kernel::<true, _>(ray, wavelength_nm, direction, StopMode::Open, &ones, |i, _, local| {
            hits[i] = local
        })?;
        Ok(hits)
    }

    /// The trace kernel: `visit` sees each surface's index, hit point (lens frame) and hit
    /// point in the surface's frame (x, y). `SOFT`: rims do not stop the ray, they lower the
    /// returned clearance (see [`Lens::trace_soft`]); otherwise the clearance is +∞.
    #[inline]
    fn trace_kernel<const SOFT: bool, F: FnMut(usize, DVec3, DVec2)>(
        &self,
        ray: &Ray,
        wavelength_nm: f64,
        direction: TraceDirection,
        stop: StopMode,
        weights: &[f64],
        mut visit: F,
    ) -> Result<(Traced, f64), Absorbed> {
        let n = self.surfaces.len();
        let mut o = ray.origin;
        let mut d = ray.direction;
        let mut transmission = 1.0;
        let mut stop_point = DVec2::ZERO;
        let mut clearance = f64::INFINITY;
        for step in 0..n {
            let i = match direction {
                TraceDirection::SceneToFilm => step,
                TraceDirection::FilmToScene => n - 1 - step,
            };
            let s = &self.surfaces[i];
            // 1. Into a misaligned element's own frame, then intersect in the surface's frame.
            if let Some(pl) = &s.placement {
                o = pl.point_to_element(o);
                d = pl.rotation.transpose() * d;
            }
            let local = DVec3::new(o.x, o.y, o.z - s.z_mm);
            let t = s.shape.intersect(local, d).ok_or(Absorbed::Missed(i))?;
            let p = local + t * d;
            let hit = DVec3::new(p.x, p.y, p.z + s.z_mm);
            visit(i, s.placement.as_ref().map_or(hit, |pl| pl.point_to_lens(hit)), DVec2::new(p.x, p.y));
            let r2 = p.x * p.x + p.y * p.y;
            // 2. Clip by the housing / clear aperture (soft: lower the clearance instead).
            if SOFT {
                let rim = if s.is_stop { s.housing_semi_diameter_mm } else { s.semi_diameter_mm };
                let mut c = rim - r2.sqrt();
                if s.is_stop {
                    stop_point = DVec2::new(p.x, p.y);
                    if stop == StopMode::Apply {
                        let (opening, tr) = self.aperture.clearance_mm(p.x, p.y, self.stop_semi_diameter_mm);
                        c = c.min(opening);
                        transmission *= tr;
                    }
                }
                clearance = clearance.min(c * weights[i]);
            } else if s.is_stop {
                if r2 > s.housing_semi_diameter_mm * s.housing_semi_diameter_mm {
                    return Err(Absorbed::Clipped(i));
                }
                stop_point = DVec2::new(p.x, p.y);
                if stop == StopMode::Apply {
                    let tr = self.aperture.transmission(p.x, p.y, self.stop_semi_diameter_mm);
                    if tr <= 0.0 {
                        return Err(Absorbed::Stop);
                    }
                    transmission *= tr;
                }
            } else if r2 > s.semi_diameter_mm * s.semi_diameter_mm {
                return Err(Absorbed::Clipped(i));
            }
            // 3. Refract (a stop is usually a plane in air, where nothing happens).
            let (n1, n2) = match direction {
                TraceDirection::SceneToFilm => {
                    (self.index_before(i, wavelength_nm), self.index_after(i, wavelength_nm))
                }
                TraceDirection::FilmToScene => {
                    (self.index_after(i, wavelength_nm), self.index_before(i, wavelength_nm))
                }
            };
            if n1 != n2 {
                let normal = s.shape.normal(p).ok_or(Absorbed::Missed(i))?;
                d = refract(d, normal, n1, n2).ok_or(Absorbed::TotalInternalReflection(i))?;
            }
            // 4. Back to the lens frame.
            o = hit;
            if let Some(pl) = &s.placement {
                o = pl.point_to_lens(o);
                d = pl.rotation * d;
            }
        }
        if !(o.is_finite() && d.is_finite()) {
            return Err(Absorbed::Missed(n));
        }
        Ok((Traced { ray: Ray { origin: o, direction: d }, transmission, stop_point }, clearance))
    }

    /// Paraxial image distance from the last vertex for an object `distance_mm` in front of
    /// the entrance pupil (`None` = infinity). Errors when no real image forms.
    pub fn focus_image_distance_mm(&self, distance_mm: Option<f64>) -> Result<f64> {
        let px = self.paraxial();
        if px.efl_mm < 0.0 && !(px.efl_x_mm > 0.0) {
            return Err(Error::Optics(format!(
                "{}: '{}' is a diverging lens (focal length {:.3} mm): it forms no real image to focus on a sensor",
                self.source_label,
                self.name(),
                px.efl_mm
            )));
        }
        match distance_mm {
            None => Ok(self.paraxial().bfl_mm),
            Some(d) => {
                if !(d.is_finite() && d > 0.0) {
                    return Err(Error::Optics(format!("focus distance must be positive, got {d} mm")));
                }
                let object_z = self.paraxial().entrance_pupil_z_mm - d;
                if object_z >= 0.0 {
                    return Err(Error::Optics(format!(
                        "cannot focus at {:.4} m: the object would be behind the front element",
                        d * 1e-3
                    )));
                }
                paraxial::image_distance_mm(self, object_z, self.primary_wavelength_nm).map_err(|_| {
                    let front_m = (self.paraxial().entrance_pupil_z_mm - self.paraxial().front_focal_z_mm) * 1e-3;
                    Error::Optics(if front_m.is_finite() {
                        format!(
                            "cannot focus at {:.4} m: closer than the lens's front focal point ({front_m:.4} m from the entrance pupil)",
                            d * 1e-3
                        )
                    } else {
                        // no finite focal point (no power): say so instead of printing NaN
                        format!("cannot focus at {:.4} m: the lens forms no real image of it", d * 1e-3)
                    })
                })
            }
        }
    }
}

/// Checks that the surfaces are real: sag defined over each clear aperture and no two
/// consecutive surfaces crossing inside their common aperture.
fn check_geometry(surfaces: &[LensSurface], map: &SourceMap) -> Result<()> {
    for (i, s) in surfaces.iter().enumerate() {
        if s.shape.sag(s.semi_diameter_mm, 0.0).is_none() || s.shape.sag(0.0, s.semi_diameter_mm).is_none() {
            return Err(map.surface_error(
                i,
                "semi_diameter_mm",
                format!(
                    "{} mm is larger than the surface allows (radius of curvature {:.6} mm, conic {})",
                    s.semi_diameter_mm,
                    1.0 / s.shape.paraxial_curvature_per_mm(),
                    s.shape.conic
                ),
            ));
        }
    }
    for i in 0..surfaces.len().saturating_sub(1) {
        let (a, b) = (&surfaces[i], &surfaces[i + 1]);
        let r_max = a.semi_diameter_mm.min(b.semi_diameter_mm);
        // Surfaces may touch (a contact ring), but must not cross by more than 1 µm.
        for k in 0..=64 {
            let r = r_max * k as f64 / 64.0;
            for (x, y) in [(r, 0.0), (0.0, r)] {
                let za = a.z_mm + a.shape.sag(x, y).unwrap_or(0.0);
                let zb = b.z_mm + b.shape.sag(x, y).unwrap_or(0.0);
                if zb < za - 1e-3 {
                    let what = if a.material_after == Material::Air { "air gap" } else { "element" };
                    return Err(map.surface_error(
                        i,
                        "thickness_mm",
                        format!(
                            "surfaces {} and {} intersect at height {:.3} mm ({what} thickness {:.4} mm < 0)",
                            i + 1,
                            i + 2,
                            r,
                            zb - za
                        ),
                    ));
                }
            }
        }
    }
    Ok(())
}
