//! The capture manifest and the forward model: errors name the capture and field; a point
//! source images where and how the lens says.

use glam::DVec2;
use petzval_fit::forward::{land, splat, Aim, Frame, Geometry, Pattern};
use petzval_fit::manifest::DistancesFrom;
use petzval_fit::{CameraParams, Manifest, Model, Param, SensorSpec};
use std::path::Path;

const GOOD: &str = r#"
[lens]
start = "double-gauss-50mm"

[sensor]
width_mm = 36.0
height_mm = 24.0
pixels = [6000, 4000]

[[free]]
param = "surface.3.radius_mm"
min = 20.5
max = 22.5

[[free]]
param = "sensor.tilt_x_deg"
min = -1.0
max = 1.0

[[capture]]
image = "captures/c01.exr"
transfer = "linear"
crop_origin_px = [2936, 1936]
source_m = [0.0, 0.0, 3.0]
focus_m = 2.0
distances_from = "sensor"
f_number = 2.8
wavelength_nm = 550
exposure = 1.0
dark_frame = "captures/dark.exr"
mask = "captures/c01_mask.png"

[[capture]]
image = "captures/c02.exr"
crop_origin_px = [0, 0]
source_m = [0.5, 0.2, 3.0]
focus_m = 2.0
f_number = "open"
wavelength_nm = "rgb"
"#;

/// A manifest error at the start of a line names that line (it named the line before), and a
/// start lens given as a relative file is the manifest's neighbour, wherever the fit runs.
#[test]
fn errors_name_the_line_and_start_lenses_are_relative_to_the_manifest() {
    let bad = GOOD.replacen("exposure = 1.0\n", "exposure = 1.0\nfocal_length = 50\n", 1);
    let line = bad.lines().position(|l| l.starts_with("focal_length")).unwrap() + 1;
    let e = Manifest::parse(&bad, Path::new("/shots/m.toml")).unwrap_err().to_string();
    assert!(e.contains(&format!("m.toml:{line}:")) && e.contains("focal_length"), "{e} (line {line})");
    let rel = GOOD.replacen("start = \"double-gauss-50mm\"", "start = \"lenses/mine.zmx\"", 1);
    let m = Manifest::parse(&rel, Path::new("/shots/m.toml")).unwrap();
    assert_eq!(m.start_lens, "/shots/lenses/mine.zmx");
    let m = Manifest::parse(GOOD, Path::new("/shots/m.toml")).unwrap();
    assert_eq!(m.start_lens, "double-gauss-50mm", "a library name stays a name");
    // the same image at the same crop twice is refused; at another crop it is another source
    let twice = GOOD.replacen("captures/c02.exr", "captures/c01.exr", 1).replacen("[0, 0]", "[2936, 1936]", 1);
    let e = Manifest::parse(&twice, Path::new("/shots/m.toml")).unwrap_err().to_string();
    assert!(e.contains("capture[2]") && e.contains("capture[1]"), "{e}");
    let other_crop = GOOD.replacen("captures/c02.exr", "captures/c01.exr", 1);
    assert!(Manifest::parse(&other_crop, Path::new("/shots/m.toml")).is_ok());
}

#[test]
fn the_issue_example_parses() {
    let m = Manifest::parse(GOOD, Path::new("/shots/manifest.toml")).unwrap();
    assert_eq!(m.start_lens, "double-gauss-50mm");
    assert_eq!(m.free.len(), 2);
    assert_eq!(m.free[0].param, Param::Surface { index: 3, field: petzval_fit::params::SurfaceField::RadiusMm });
    assert_eq!(m.captures[0].image, Path::new("/shots/captures/c01.exr"));
    assert_eq!(m.captures[1].f_number, petzval_fit::manifest::FNumber::Open);
    assert_eq!(m.captures[1].wavelength, petzval_fit::manifest::Wavelength::Rgb);
    assert_eq!(m.captures[1].distances_from, DistancesFrom::Sensor);
    assert_eq!(m.captures[1].exposure, 1.0);
    let (px, py) = m.sensor.pitch_mm();
    assert!((px - 0.006).abs() < 1e-12 && (py - 0.006).abs() < 1e-12);
}

#[test]
fn bad_manifests_name_the_capture_and_field() {
    for (from, to, wanted) in [
        ("f_number = 2.8", "f_number = -2.8", "capture[1] (captures/c01.exr).f_number"),
        ("f_number = 2.8", "f_number = \"wide\"", "capture[1] (captures/c01.exr).f_number"),
        ("wavelength_nm = 550", "wavelength_nm = 1550", "capture[1] (captures/c01.exr).wavelength_nm"),
        ("source_m = [0.0, 0.0, 3.0]", "source_m = [0.0, 0.0, -3.0]", "capture[1] (captures/c01.exr).source_m"),
        ("focus_m = 2.0\ndistances_from", "focus_m = nan\ndistances_from", "capture[1] (captures/c01.exr).focus_m"),
        ("pixels = [6000, 4000]", "pixels = [6000, 3000]", "sensor.pixels"),
        ("param = \"surface.3.radius_mm\"", "param = \"surface.3.radius\"", "free[1].param"),
        ("param = \"surface.3.radius_mm\"", "param = \"surface.0.radius_mm\"", "free[1].param"),
        ("min = 20.5\nmax = 22.5", "min = 22.5\nmax = 20.5", "free[1].min"),
        ("exposure = 1.0", "exposure = 1.0\nexposure_time = 2", "manifest"),
    ] {
        assert!(GOOD.contains(from), "{from}");
        let text = GOOD.replacen(from, to, 1);
        let err = Manifest::parse(&text, Path::new("m.toml")).unwrap_err().to_string();
        assert!(err.contains(wanted), "{to}: {err} should name {wanted}");
        assert!(err.starts_with("m.toml"), "{err} should name the file");
    }
}

#[test]
fn parameters_read_and_write_the_prescription() {
    let lens = petzval_optics::library_lens("double-gauss-50mm").unwrap();
    let mut model = Model::new(lens.prescription().clone());
    for name in ["surface.3.radius_mm", "surface.1.nd", "surface.4.tilt_y_deg", "stop.position_mm", "focus.scale"] {
        let p: Param = name.parse().unwrap();
        assert_eq!(p.to_string(), name);
        let v = model.get(&p).unwrap();
        model.set(&p, v + 0.01).unwrap();
        assert!((model.get(&p).unwrap() - (v + 0.01)).abs() < 1e-12, "{name}");
    }
    // the stop moves, the lens keeps its length
    let total: f64 = model.prescription.surfaces.iter().map(|s| s.thickness_mm).sum();
    let total0: f64 = lens.prescription().surfaces.iter().map(|s| s.thickness_mm).sum();
    assert!((total - total0).abs() < 1e-9);
    assert!(model.get(&"surface.99.radius_mm".parse().unwrap()).is_err());
}

/// The image of a point source: upright (right and up of the centre for a source right of and
/// above the axis), sharp at the focus distance and blurred away from it, with the light of the
/// pupil area (f/4 gathers four times f/8's on the axis).
#[test]
fn a_point_source_images_where_the_lens_says() {
    let sensor = SensorSpec { width_mm: 36.0, height_mm: 24.0, pixels: [6000, 4000] };
    let frame = Frame { sensor, crop_origin_px: [2936, 1936], width: 128, height: 128 };
    let camera = CameraParams::default();
    let open = petzval_optics::library_lens("double-gauss-50mm").unwrap();
    let pattern = Pattern::spiral(8192);
    let image = |lens: &petzval_optics::Lens, source: [f64; 3], focus: f64| {
        let g = Geometry::new(lens, &camera, source, focus, DistancesFrom::Sensor).unwrap();
        let aim = Aim::find(lens, g.source_mm, 550.0).unwrap();
        let landing = land(lens, &camera, None, &g, &aim, &pattern, 550.0, &frame);
        splat(&landing, DVec2::ZERO, 1.0, frame.width, frame.height)
    };
    let stats = |img: &[f64]| {
        let total: f64 = img.iter().sum();
        let (mut cx, mut cy) = (0.0, 0.0);
        for (k, v) in img.iter().enumerate() {
            cx += v * ((k % 128) as f64 + 0.5);
            cy += v * ((k / 128) as f64 + 0.5);
        }
        let (cx, cy) = (cx / total, cy / total);
        let mut r2 = 0.0;
        for (k, v) in img.iter().enumerate() {
            r2 += v * (((k % 128) as f64 + 0.5 - cx).powi(2) + ((k / 128) as f64 + 0.5 - cy).powi(2));
        }
        (total, cx, cy, (r2 / total).sqrt())
    };
    let f8 = open.stopped_down(8.0).unwrap();
    let f4 = open.stopped_down(4.0).unwrap();
    // on the axis, in focus: the image centre of the full sensor (3000, 2000) is (64, 64) here
    let (t8, cx, cy, r) = stats(&image(&f8, [0.0, 0.0, 2.0], 2.0));
    assert!((cx - 64.0).abs() < 0.05 && (cy - 64.0).abs() < 0.05, "centroid ({cx}, {cy})");
    assert!(r < 1.0, "in focus the spot is under a pixel (rms {r} px)");
    // out of focus: a disc
    let (_, _, _, r_blur) = stats(&image(&f8, [0.0, 0.0, 1.0], 2.0));
    assert!(r_blur > 4.0 * r.max(0.5), "defocused rms {r_blur} px vs focused {r}");
    // upright: right of and above the axis shows right of and above the centre
    let (_, cx, cy, _) = stats(&image(&f8, [0.01, 0.006, 2.0], 2.0));
    assert!(cx > 64.0 + 5.0 && cy < 64.0 - 3.0, "({cx}, {cy})");
    // twice the aperture diameter, four times the light
    let (t4, ..) = stats(&image(&f4, [0.0, 0.0, 2.0], 2.0));
    assert!((t4 / t8 / 4.0 - 1.0).abs() < 0.03, "f/4 over f/8 light: {}", t4 / t8);
}

/// An EXR capture without R, G, B or Y channels (a render's layer-prefixed `diffuse.R`, ...) is
/// refused naming the channels it has (the message named none).
#[test]
fn an_exr_without_rgb_or_y_names_its_channels() {
    use exr::prelude::*;
    let dir = std::env::temp_dir().join(format!("petzval-fit-exr-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let ch = |name: &str| AnyChannel::new(name, FlatSamples::F32(vec![0.5f32; 16]));
    let channels = AnyChannels::sort(SmallVec::from_vec(vec![ch("diffuse.R"), ch("diffuse.G"), ch("diffuse.B")]));
    let layer = Layer::new((4, 4), LayerAttributes::default(), Encoding::FAST_LOSSLESS, channels);
    Image::from_layer(layer).write().to_file(dir.join("layered.exr")).unwrap();
    let text = GOOD.replacen("captures/c01.exr", "layered.exr", 1);
    let m = Manifest::parse(&text, &dir.join("m.toml")).unwrap();
    let e = petzval_fit::captures::load(&m.captures[0]).expect_err("refused").to_string();
    assert!(e.contains("layered.exr") && e.contains("diffuse.R") && e.contains("diffuse.B"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

/// An 8-bit capture left at the default transfer is read as linear with a warning (camera
/// JPEGs and 8-bit PNGs are sRGB-encoded); none when the manifest says `transfer`, or for a
/// 16-bit file.
#[test]
fn an_eight_bit_capture_read_as_linear_by_default_is_warned_about() {
    let dir = std::env::temp_dir().join(format!("petzval-fit-8bit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    image::GrayImage::from_fn(8, 8, |x, y| image::Luma([(x * 20 + y) as u8])).save(dir.join("c8.png")).unwrap();
    image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(8, 8, |x, _| image::Luma([x as u16 * 4000]))
        .save(dir.join("c16.png"))
        .unwrap();
    let case = |image: &str, transfer: Option<&str>| {
        let mut text =
            GOOD.replacen("captures/c01.exr", image, 1).replacen("dark_frame = \"captures/dark.exr\"\n", "", 1);
        text = text.replacen("mask = \"captures/c01_mask.png\"\n", "", 1);
        text = match transfer {
            Some(t) => text.replacen("transfer = \"linear\"", &format!("transfer = \"{t}\""), 1),
            None => text.replacen("transfer = \"linear\"\n", "", 1),
        };
        let m = Manifest::parse(&text, &dir.join("m.toml")).unwrap();
        let img = petzval_fit::captures::load(&m.captures[0]).unwrap();
        petzval_fit::captures::transfer_warning(&m.captures[0], &img)
    };
    let w = case("c8.png", None).expect("a warning for an 8-bit file read as linear by default");
    assert!(w.contains("c8.png") && w.contains("srgb"), "{w}");
    assert_eq!(case("c8.png", Some("linear")), None);
    assert_eq!(case("c8.png", Some("srgb")), None);
    assert_eq!(case("c16.png", None), None);
    std::fs::remove_dir_all(&dir).ok();
}

/// A camera JPEG (8-bit RGB, how most photographs arrive) is read: its size and three
/// channels, flagged 8-bit so that an unstated transfer is warned about.
#[test]
fn a_jpeg_capture_is_read() {
    let dir = std::env::temp_dir().join(format!("petzval-fit-jpeg-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    image::RgbImage::from_fn(32, 16, |x, y| image::Rgb([(x * 6) as u8, (y * 12) as u8, 128]))
        .save(dir.join("c.jpg"))
        .unwrap();
    let text = GOOD
        .replacen("captures/c01.exr", "c.jpg", 1)
        .replacen("dark_frame = \"captures/dark.exr\"\n", "", 1)
        .replacen("mask = \"captures/c01_mask.png\"\n", "", 1)
        .replacen("transfer = \"linear\"\n", "", 1)
        .replacen("wavelength_nm = 550", "wavelength_nm = \"rgb\"", 1);
    let m = Manifest::parse(&text, &dir.join("m.toml")).unwrap();
    let img = petzval_fit::captures::load(&m.captures[0]).unwrap();
    assert_eq!((img.width, img.height, img.channels.len()), (32, 16, 3));
    assert!(img.eight_bit);
    // the flat blue channel (level 128) survives the compression within a few levels
    let blue = img.channels[2].iter().sum::<f64>() / img.channels[2].len() as f64;
    assert!((blue - 128.0).abs() < 4.0, "blue mean {blue}");
    assert!(petzval_fit::captures::transfer_warning(&m.captures[0], &img).is_some_and(|w| w.contains("c.jpg")));
    std::fs::remove_dir_all(&dir).ok();
}

/// A floating-point TIFF (grey or RGB, as raw converters write them) is read as linear values
/// with no clipping level, as an EXR is: the values come back exactly, and none is masked.
#[test]
fn a_float_tiff_capture_is_read_as_linear_values() {
    use tiff::encoder::{colortype, TiffEncoder};
    let dir = std::env::temp_dir().join(format!("petzval-fit-ftiff-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let grey: Vec<f32> = (0..48).map(|k| k as f32 * 1.5e4 + 0.25).collect(); // up to 7e5: past 16-bit
    let rgb: Vec<f32> = (0..48 * 3).map(|k| (k % 7) as f32 * 0.125 + (k / 3) as f32).collect();
    let write = |name: &str, rgb_file: bool| {
        let f = std::fs::File::create(dir.join(name)).unwrap();
        let mut enc = TiffEncoder::new(f).unwrap();
        if rgb_file {
            enc.write_image::<colortype::RGB32Float>(8, 6, &rgb).unwrap();
        } else {
            enc.write_image::<colortype::Gray32Float>(8, 6, &grey).unwrap();
        }
    };
    write("grey.tif", false);
    write("rgb.tif", true);
    let load = |image: &str, wavelength: &str| {
        let text = GOOD
            .replacen("captures/c01.exr", image, 1)
            .replacen("dark_frame = \"captures/dark.exr\"\n", "", 1)
            .replacen("mask = \"captures/c01_mask.png\"\n", "", 1)
            .replacen("wavelength_nm = 550", &format!("wavelength_nm = {wavelength}"), 1);
        let m = Manifest::parse(&text, &dir.join("m.toml")).unwrap();
        petzval_fit::captures::load(&m.captures[0]).unwrap()
    };
    let g = load("grey.tif", "550");
    assert_eq!((g.width, g.height, g.channels.len(), g.clipped), (8, 6, 1, 0));
    assert!(g.channels[0].iter().zip(&grey).all(|(a, b)| *a == *b as f64));
    let c = load("rgb.tif", "\"rgb\"");
    assert_eq!((c.width, c.height, c.channels.len(), c.clipped), (8, 6, 3, 0));
    for ch in 0..3 {
        assert!(c.channels[ch].iter().enumerate().all(|(k, v)| *v == rgb[k * 3 + ch] as f64), "channel {ch}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// GOOD with its first capture's image replaced, no dark frame or mask, and `extra` lines
/// added to that capture; parsed as `dir/m.toml`.
fn one_capture(dir: &Path, image: &str, extra: &str) -> Manifest {
    let text = GOOD
        .replacen("captures/c01.exr", image, 1)
        .replacen("dark_frame = \"captures/dark.exr\"\n", "", 1)
        .replacen("mask = \"captures/c01_mask.png\"\n", "", 1)
        .replacen("exposure = 1.0\n", &format!("exposure = 1.0\n{extra}"), 1);
    Manifest::parse(&text, &dir.join("m.toml")).unwrap()
}

fn temp_dir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("petzval-fit-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A hot pixel (60 301) brighter than a faint, spread spot's peak (6 000; its best 3×3 sum
/// below the hot pixel's) is masked, and the spot kept (the hot pixel was taken for the
/// source and kept, the spot left as background).
#[test]
fn a_hot_pixel_brighter_than_a_faint_spot_is_masked_and_the_spot_kept() {
    let dir = temp_dir("hot");
    let (w, h) = (40u32, 32u32);
    let (sx, sy, hx, hy) = (26u32, 12u32, 7u32, 22u32);
    let mut seed = 12345u32;
    let img = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(w, h, |x, y| {
        seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        let noise = (seed >> 28) as f64; // 0..15
        let r2 = (x as f64 - sx as f64).powi(2) + (y as f64 - sy as f64).powi(2);
        let v = 100.0 + noise + 6000.0 * (-r2 / (2.0 * 1.6f64.powi(2))).exp();
        image::Luma([if (x, y) == (hx, hy) { 60301 } else { v.round() as u16 }])
    });
    img.save(dir.join("hot.png")).unwrap();
    let m = one_capture(&dir, "hot.png", "");
    let c = petzval_fit::captures::load(&m.captures[0]).unwrap();
    let at = |x: u32, y: u32| (y * w + x) as usize;
    assert!(!c.mask[at(hx, hy)], "the hot pixel is masked");
    assert_eq!(c.hot, 1);
    for dy in 0..5 {
        for dx in 0..5 {
            assert!(c.mask[at(sx + dx - 2, sy + dy - 2)], "spot pixel ({}, {}) kept", sx + dx - 2, sy + dy - 2);
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// A free parameter without `start` whose start-lens value lies outside its bounds is refused,
/// naming the manifest, the [[free]] entry, its bounds and the lens's value (it was accepted,
/// and the fit started outside its bounds).
#[test]
fn a_free_parameter_whose_lens_value_is_outside_its_bounds_is_refused() {
    let text = GOOD.replacen("min = 20.5\nmax = 22.5", "min = 30.5\nmax = 31.5", 1);
    let m = Manifest::parse(&text, Path::new("/shots/m.toml")).unwrap();
    let lens = petzval_optics::load_lens("double-gauss-50mm").unwrap();
    let value = Model::new(lens.prescription().clone()).get(&"surface.3.radius_mm".parse().unwrap()).unwrap();
    let e = match petzval_fit::fit::Problem::new(&m, &petzval_fit::fit::FitOptions::default()) {
        Ok(_) => panic!("a start outside the bounds was accepted"),
        Err(e) => e.to_string(),
    };
    assert!(e.starts_with("/shots/m.toml: free[1]"), "{e}");
    assert!(e.contains("30.5") && e.contains("31.5") && e.contains(&value.to_string()), "{e} (lens value {value})");
}

/// A JPEG's clipped core, which its ringing keeps a few levels below 255, is masked by the
/// default saturation (245 for JPEG; 255 masked part of it only); an explicit saturation
/// still wins.
#[test]
fn a_clipped_jpeg_core_is_masked_by_default() {
    let dir = temp_dir("jpegclip");
    let (w, h) = (48u32, 48u32);
    // a spot 4× over the clipping level: a plateau of 255 with soft shoulders
    let truth = |x: u32, y: u32| {
        let r2 = (x as f64 - 23.5).powi(2) + (y as f64 - 23.5).powi(2);
        20.0 + 1000.0 * (-r2 / (2.0 * 5.0f64.powi(2))).exp()
    };
    let img = image::GrayImage::from_fn(w, h, |x, y| image::Luma([truth(x, y).min(255.0) as u8]));
    let file = std::fs::File::create(dir.join("clip.jpg")).unwrap();
    img.write_with_encoder(image::codecs::jpeg::JpegEncoder::new_with_quality(file, 95)).unwrap();
    let c = load_first(&one_capture(&dir, "clip.jpg", ""));
    // the core: where the light was at least twice the clipping level
    let core: Vec<usize> = (0..w * h).filter(|k| truth(k % w, k / w) > 510.0).map(|k| k as usize).collect();
    assert!(core.len() > 50);
    // the evidence: after compression part of the core is below 255 (a quality-95 file: 249 to 254)
    assert!(core.iter().any(|&k| c.channels[0][k] < 255.0), "the core has values below 255");
    assert!(core.iter().all(|&k| !c.mask[k]), "the clipped core is masked ({} clipped)", c.clipped);
    let at_255 = load_first(&one_capture(&dir, "clip.jpg", "saturation = 255.0\n"));
    assert!(at_255.clipped < c.clipped, "an explicit saturation wins: {} at 255", at_255.clipped);
    let explicit = load_first(&one_capture(&dir, "clip.jpg", "saturation = 1000.0\n"));
    assert_eq!(explicit.clipped, 0);
    std::fs::remove_dir_all(&dir).ok();
}

/// `load` of a manifest's first capture.
fn load_first(m: &Manifest) -> petzval_fit::captures::CaptureImage {
    petzval_fit::captures::load(&m.captures[0]).unwrap()
}

/// Errors of the images name the manifest, the capture and the field before the file, as
/// manifest errors do (they named the file only).
#[test]
fn image_errors_name_the_manifest_the_capture_and_the_field() {
    use exr::prelude::*;
    let dir = temp_dir("imgerr");
    image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(16, 16, |x, y| image::Luma([(x * 100 + y) as u16]))
        .save(dir.join("grey.png"))
        .unwrap();
    image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_pixel(8, 8, image::Luma([7]))
        .save(dir.join("small.png"))
        .unwrap();
    let bytes = std::fs::read(dir.join("grey.png")).unwrap();
    std::fs::write(dir.join("trunc.png"), &bytes[..bytes.len() / 2]).unwrap();
    std::fs::write(dir.join("empty.png"), b"").unwrap();
    std::fs::write(dir.join("text.png"), b"not an image").unwrap();
    std::fs::create_dir_all(dir.join("folder.png")).unwrap();
    let mut values = vec![0.5f32; 16];
    values[5] = f32::NAN;
    let ch = AnyChannel::new("Y", FlatSamples::F32(values));
    let layer = Layer::new(
        (4, 4),
        LayerAttributes::default(),
        Encoding::FAST_LOSSLESS,
        AnyChannels::sort(SmallVec::from_vec(vec![ch])),
    );
    Image::from_layer(layer).write().to_file(dir.join("nan.exr")).unwrap();
    let m_file = dir.join("m.toml").display().to_string();
    let cases = [
        ("nope.png", "", "image", "nope.png"),
        ("trunc.png", "", "image", "trunc.png"),
        ("empty.png", "", "image", "empty.png"),
        ("text.png", "", "image", "text.png"),
        ("folder.png", "", "image", "folder.png"),
        ("nan.exr", "", "image", "nan.exr"),
        ("grey.png", "dark_frame = \"small.png\"\n", "dark_frame", "small.png"),
        ("grey.png", "dark_frame = \"nodark.png\"\n", "dark_frame", "nodark.png"),
        ("grey.png", "mask = \"small.png\"\n", "mask", "small.png"),
    ];
    for (image, extra, field, file) in cases {
        let m = one_capture(&dir, image, extra);
        let e = petzval_fit::captures::load(&m.captures[0]).expect_err(image).to_string();
        let head = format!("{m_file}: capture[1] ({image}).{field}: ");
        assert!(e.starts_with(&head) && e.contains(file), "{e} (expected {head}…{file})");
    }
    let rgb = one_capture(&dir, "grey.png", "").captures.remove(0);
    let rgb = petzval_fit::Capture { wavelength: petzval_fit::manifest::Wavelength::Rgb, ..rgb };
    let e = petzval_fit::captures::load(&rgb).expect_err("rgb on grey").to_string();
    assert!(e.starts_with(&format!("{m_file}: capture[1] (grey.png).wavelength_nm: ")), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

/// A dark frame of another bit depth than its capture (8-bit capture, 16-bit dark) is refused
/// naming the capture and the field (it was subtracted in the wrong units); the same depth is
/// subtracted.
#[test]
fn a_dark_frame_of_another_bit_depth_is_refused() {
    let dir = temp_dir("darkdepth");
    image::GrayImage::from_fn(16, 16, |x, y| image::Luma([(x * 10 + y) as u8])).save(dir.join("c8.png")).unwrap();
    image::GrayImage::from_pixel(16, 16, image::Luma([3])).save(dir.join("d8.png")).unwrap();
    image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_pixel(16, 16, image::Luma([800]))
        .save(dir.join("d16.png"))
        .unwrap();
    let m = one_capture(&dir, "c8.png", "dark_frame = \"d16.png\"\n");
    let e = petzval_fit::captures::load(&m.captures[0]).expect_err("16-bit dark under 8-bit").to_string();
    assert!(e.contains("capture[1] (c8.png).dark_frame") && e.contains("8-bit") && e.contains("16-bit"), "{e}");
    let c = load_first(&one_capture(&dir, "c8.png", "dark_frame = \"d8.png\"\n"));
    assert_eq!(c.channels[0][1], 10.0 - 3.0);
    std::fs::remove_dir_all(&dir).ok();
}
