//! Optical glass: an embedded catalogue of dispersion formulas and a model glass from (nd, Vd).
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | wavelength | f64 | nm, 380..=780 supported | 587.5618 (helium d line) |
//! | `nd` | f64 | refractive index at the d line | — |
//! | `vd` | f64 | Abbe number (nd - 1) / (nF - nC) | — |
//!
//! The catalogue (`renderer/optics/data/glass_catalog.tsv`) holds the coefficients of every glass the
//! lens library names, taken from the refractiveindex.info database (CC0), the manufacturers'
//! data sheets as republished there. A model glass from (nd, Vd) uses a two-term Cauchy
//! formula through nd with the given F-C dispersion, which is exact at d and matches the
//! dispersion between F and C.

use crate::error::{Error, Result};
use std::sync::OnceLock;

/// Helium d line, the reference wavelength of nd.
pub const WAVELENGTH_D_NM: f64 = 587.5618;
/// Hydrogen F line.
pub const WAVELENGTH_F_NM: f64 = 486.1327;
/// Hydrogen C line.
pub const WAVELENGTH_C_NM: f64 = 656.2725;

/// A dispersion formula, with wavelengths in micrometres as in the catalogues.
#[derive(Debug, Clone, PartialEq)]
pub enum Dispersion {
    /// n² = 1 + Σ Bᵢ λ² / (λ² − Cᵢ)  (refractiveindex.info formula 2; Cᵢ in µm²).
    Sellmeier {
        /// B coefficients.
        b: Vec<f64>,
        /// C coefficients (µm²).
        c: Vec<f64>,
    },
    /// n² = A0 + A1 λ² + A2 λ⁻² + A3 λ⁻⁴ + A4 λ⁻⁶ + A5 λ⁻⁸ (Schott / CDGM "formula 3").
    Schott {
        /// A0..A5.
        a: [f64; 6],
    },
    /// n² = A0 + Σ cᵢ λ^eᵢ: refractiveindex.info "formula 3" in general, for glasses whose
    /// polynomial has terms the Schott form lacks (HIKARI's λ⁴ term).
    Polynomial {
        /// Constant term A0.
        a0: f64,
        /// (coefficient, exponent) pairs.
        terms: Vec<(f64, f64)>,
    },
    /// n = nd + (nF − nC) · (λ⁻² − λd⁻²) / (λF⁻² − λC⁻²): the model glass.
    Cauchy {
        /// Index at the d line.
        nd: f64,
        /// Abbe number.
        vd: f64,
    },
}

impl Dispersion {
    /// Refractive index at `wavelength_nm`.
    pub fn index(&self, wavelength_nm: f64) -> f64 {
        let l_um = wavelength_nm * 1e-3;
        let l2 = l_um * l_um;
        match self {
            Dispersion::Sellmeier { b, c } => {
                let mut n2 = 1.0;
                for (bi, ci) in b.iter().zip(c) {
                    n2 += bi * l2 / (l2 - ci);
                }
                n2.sqrt()
            }
            Dispersion::Schott { a } => {
                let il2 = 1.0 / l2;
                (a[0] + a[1] * l2 + il2 * (a[2] + il2 * (a[3] + il2 * (a[4] + il2 * a[5])))).sqrt()
            }
            Dispersion::Polynomial { a0, terms } => {
                (a0 + terms.iter().map(|(c, e)| c * l_um.powf(*e)).sum::<f64>()).sqrt()
            }
            Dispersion::Cauchy { nd, vd } => {
                let inv2 = |l_nm: f64| 1.0 / (l_nm * 1e-3).powi(2);
                let nf_minus_nc = (nd - 1.0) / vd;
                let slope = nf_minus_nc / (inv2(WAVELENGTH_F_NM) - inv2(WAVELENGTH_C_NM));
                nd + slope * (inv2(wavelength_nm) - inv2(WAVELENGTH_D_NM))
            }
        }
    }
}

/// An optical material: air (n = 1, indices are relative to air as in lens catalogues) or a glass.
#[derive(Debug, Clone, PartialEq)]
pub enum Material {
    /// Air, n = 1.
    Air,
    /// A catalogue glass.
    Catalog {
        /// Catalogue name as written in the catalogue (e.g. `N-BK7`).
        name: String,
        /// Manufacturer (`schott`, `ohara`, `hoya`, `cdgm`, ...).
        catalogue: String,
        /// Its dispersion.
        dispersion: Dispersion,
    },
    /// A model glass from (nd, Vd); Vd = 0 or absent means no dispersion.
    Model {
        /// Index at the d line.
        nd: f64,
        /// Abbe number (0 = no dispersion).
        vd: f64,
    },
}

impl Material {
    /// Refractive index at `wavelength_nm`.
    pub fn index(&self, wavelength_nm: f64) -> f64 {
        match self {
            Material::Air => 1.0,
            Material::Catalog { dispersion, .. } => dispersion.index(wavelength_nm),
            Material::Model { nd, vd } => {
                if *vd <= 0.0 {
                    *nd
                } else {
                    Dispersion::Cauchy { nd: *nd, vd: *vd }.index(wavelength_nm)
                }
            }
        }
    }

    /// Whether the index changes with wavelength.
    pub fn is_dispersive(&self) -> bool {
        match self {
            Material::Air => false,
            Material::Catalog { .. } => true,
            Material::Model { vd, .. } => *vd > 0.0,
        }
    }

    /// (nd, Vd) of this material, computed from its formula for catalogue glass.
    pub fn nd_vd(&self) -> (f64, f64) {
        let nd = self.index(WAVELENGTH_D_NM);
        let dn = self.index(WAVELENGTH_F_NM) - self.index(WAVELENGTH_C_NM);
        let vd = if dn.abs() < 1e-12 { 0.0 } else { (nd - 1.0) / dn };
        (nd, vd)
    }

    /// Looks up a catalogue glass by name (case, spaces, `-` and `_` ignored: `S-LAH59` = `SLAH59`).
    pub fn from_catalog(name: &str) -> Result<Material> {
        let key = normalize(name);
        if key == "AIR" {
            return Ok(Material::Air);
        }
        let cat = catalog();
        if let Some(g) = cat.iter().find(|g| normalize(&g.name) == key) {
            return Ok(Material::Catalog {
                name: g.name.clone(),
                catalogue: g.catalogue.clone(),
                dispersion: g.dispersion.clone(),
            });
        }
        // Suggestions: names one or two edits away (a quarter of the name's length), or that
        // contain the name or are contained in it with most of its letters; nearest first.
        let mut close: Vec<(usize, &str)> = cat
            .iter()
            .filter_map(|g| {
                let n = normalize(&g.name);
                let d = edit_distance(&n, &key);
                let (short, long) = if n.len() < key.len() { (n.len(), key.len()) } else { (key.len(), n.len()) };
                let contained = (n.contains(&key) || key.contains(&n)) && 5 * short >= 3 * long;
                (d <= (key.len() / 4).max(1) || contained).then_some((d, g.name.as_str()))
            })
            .collect();
        close.sort_by_key(|c| c.0);
        let close: Vec<&str> = close.into_iter().map(|c| c.1).take(5).collect();
        let suggestion = if close.is_empty() { String::new() } else { format!(", did you mean {}?", close.join(", ")) };
        Err(Error::UnknownGlass { name: name.to_string(), suggestion })
    }
}

/// One glass of the embedded catalogue.
#[derive(Debug, Clone)]
pub struct CatalogGlass {
    /// Name as the manufacturer writes it.
    pub name: String,
    /// Manufacturer.
    pub catalogue: String,
    /// Dispersion formula.
    pub dispersion: Dispersion,
}

/// Levenshtein distance between two names (characters).
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut diagonal = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let above = row[j + 1];
            row[j + 1] = (diagonal + usize::from(ca != *cb)).min(above + 1).min(row[j] + 1);
            diagonal = above;
        }
    }
    row[b.len()]
}

fn normalize(name: &str) -> String {
    name.chars().filter(|c| !matches!(c, '-' | '_' | ' ' | '.')).flat_map(|c| c.to_uppercase()).collect()
}

const CATALOG_TSV: &str = include_str!("../data/glass_catalog.tsv");

/// The embedded glass catalogue, parsed once.
pub fn catalog() -> &'static [CatalogGlass] {
    static CATALOG: OnceLock<Vec<CatalogGlass>> = OnceLock::new();
    CATALOG.get_or_init(|| parse_catalog(CATALOG_TSV))
}

/// Parses the catalogue table: `name  catalogue  formula  coefficients...` separated by tabs,
/// `#` comments. The file is embedded and checked by a unit test, so a bad row is a build bug.
fn parse_catalog(text: &str) -> Vec<CatalogGlass> {
    let mut out = Vec::new();
    for line in text.lines() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let cols: Vec<&str> = line.split('\t').collect();
        if cols.len() < 4 {
            continue;
        }
        let nums: Vec<f64> = cols[3..].iter().filter_map(|s| s.trim().parse().ok()).collect();
        let dispersion = match cols[2] {
            "sellmeier" if nums.len().is_multiple_of(2) => Dispersion::Sellmeier {
                b: nums.iter().step_by(2).copied().collect(),
                c: nums.iter().skip(1).step_by(2).copied().collect(),
            },
            "schott" if nums.len() == 6 => {
                let mut a = [0.0; 6];
                a.copy_from_slice(&nums);
                Dispersion::Schott { a }
            }
            "polynomial" if !nums.len().is_multiple_of(2) => {
                Dispersion::Polynomial { a0: nums[0], terms: nums[1..].chunks(2).map(|p| (p[0], p[1])).collect() }
            }
            _ => continue,
        };
        out.push(CatalogGlass { name: cols[0].to_string(), catalogue: cols[1].to_string(), dispersion });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn catalogue_rows_all_parse_and_are_physical() {
        let rows = CATALOG_TSV.lines().filter(|l| !l.trim().is_empty() && !l.trim_start().starts_with('#')).count();
        assert_eq!(rows, catalog().len(), "every catalogue row must parse");
        for g in catalog() {
            for wl in [380.0, 480.0, 587.5618, 700.0, 780.0] {
                let n = g.dispersion.index(wl);
                assert!(n.is_finite() && n > 1.2 && n < 2.5, "{} at {wl} nm: {n}", g.name);
            }
        }
    }

    #[test]
    fn polynomial_rows_give_the_makers_nd() {
        // HIKARI J-LASF015 (formula 3 with a λ⁴ term): catalogue nd 1.80400, vd 46.6
        let Ok(Material::Catalog { dispersion, .. }) = Material::from_catalog("J-LASF015") else {
            panic!("J-LASF015 must be in the catalogue");
        };
        assert!(matches!(dispersion, Dispersion::Polynomial { ref terms, .. } if terms.len() == 6), "{dispersion:?}");
        let nd = dispersion.index(WAVELENGTH_D_NM);
        assert!((nd - 1.80400).abs() < 5e-6, "nd {nd}");
        let vd = (nd - 1.0) / (dispersion.index(WAVELENGTH_F_NM) - dispersion.index(WAVELENGTH_C_NM));
        assert!((vd - 46.6).abs() < 0.05, "vd {vd}");
    }

    #[test]
    fn model_glass_hits_nd_and_vd() {
        let m = Material::Model { nd: 1.6204, vd: 60.3 };
        let (nd, vd) = m.nd_vd();
        assert!((nd - 1.6204).abs() < 1e-12);
        assert!((vd - 60.3).abs() < 1e-9);
    }

    #[test]
    fn names_are_normalised() {
        if let Ok(Material::Catalog { name, .. }) = Material::from_catalog("n_bk7") {
            assert_eq!(name, "N-BK7");
        } else {
            panic!("N-BK7 must be in the catalogue");
        }
        assert!(Material::from_catalog("NOT-A-GLASS").is_err());
    }
}
