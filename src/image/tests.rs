//! Tests of images and their files.

use std::fs;

use super::colormap::*;
use super::*;

/// A fresh temporary directory per test.
fn temp_dir() -> tempfile::TempDir {
    tempfile::tempdir().expect("creating a temporary directory")
}

/// Names of the entries of `dir`.
fn entries(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> =
        fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    names.sort();
    names
}

fn read_png(path: &Path) -> image::RgbImage {
    image::open(path).unwrap().into_rgb8()
}

/// Linear sRGB → Oklab (Ottosson 2020), to check the map's symmetry on decoded bytes.
fn linear_srgb_to_oklab([r, g, b]: [f64; 3]) -> [f64; 3] {
    let l = 0.412_221_470_8 * r + 0.536_332_536_3 * g + 0.051_445_992_9 * b;
    let m = 0.211_903_498_2 * r + 0.680_699_545_1 * g + 0.107_396_956_6 * b;
    let s = 0.088_302_461_9 * r + 0.281_718_837_6 * g + 0.629_978_700_5 * b;
    let (l, m, s) = (l.cbrt(), m.cbrt(), s.cbrt());
    [
        0.210_454_255_3 * l + 0.793_617_785_0 * m - 0.004_072_046_8 * s,
        1.977_998_495_1 * l - 2.428_592_205_0 * m + 0.450_593_709_9 * s,
        0.025_904_037_1 * l + 0.782_771_766_2 * m - 0.808_675_766_0 * s,
    ]
}

/// Inverse sRGB transfer function of a byte.
fn srgb8_to_linear(byte: u8) -> f64 {
    let e = f64::from(byte) / 255.0;
    if e <= SRGB_LINEAR_SLOPE * SRGB_LINEAR_THRESHOLD {
        e / SRGB_LINEAR_SLOPE
    } else {
        ((e + SRGB_OFFSET) / SRGB_SCALE).powf(SRGB_GAMMA)
    }
}

#[test]
fn from_rgb_checks_the_length_and_names_the_sizes() {
    let err = Image::from_rgb(4, 2, vec![0.0; 23]).unwrap_err().to_string();
    assert!(err.contains("4×2") && err.contains("24") && err.contains("23"), "{err}");
    let image = Image::from_rgb(2, 1, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
    assert_eq!(image.pixel(1, 0), [4.0, 5.0, 6.0]);
    assert_eq!(image.mean(), [2.5, 3.5, 4.5]);
}

#[test]
fn pixels_are_row_major_top_row_first() {
    let mut image = Image::new(3, 2);
    image.set_pixel(2, 1, [7.0, 8.0, 9.0]);
    assert_eq!(&image.as_slice()[15..18], &[7.0, 8.0, 9.0]);
    assert_eq!(Image::new(0, 5).mean(), [0.0; 3]);
}

#[test]
#[should_panic(expected = "outside the 3×2 image")]
fn pixel_out_of_bounds_panics() {
    Image::new(3, 2).pixel(0, 2);
}

/// Values that a lossy path would change: negatives, subnormals, huge, NaN and infinities.
fn awkward_image() -> Image {
    let specials = [-1.5, -0.0, 0.1, 1e-42, -3.0e38, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, f32::MIN_POSITIVE];
    let (width, height) = (7, 5);
    let data = (0..width * height * 3)
        .map(|i| if (i as usize) < specials.len() { specials[i as usize] } else { (i as f32 * 0.37).sin() * 10.0 })
        .collect();
    Image::from_rgb(width, height, data).unwrap()
}

fn bits(image: &Image) -> Vec<u32> {
    image.as_slice().iter().map(|v| v.to_bits()).collect()
}

#[test]
fn exr_round_trip_is_bit_exact() {
    let dir = temp_dir();
    let path = dir.path().join("a.exr");
    let image = awkward_image();
    image.write_exr(&path).unwrap();
    let back = Image::read_exr(&path).unwrap();
    assert_eq!((back.width(), back.height()), (7, 5));
    assert_eq!(bits(&back), bits(&image));
    assert_eq!(entries(dir.path()), ["a.exr"], "no temporary file is left");
}

#[test]
fn exr_reads_rgba_half_files() {
    let dir = temp_dir();
    let path = dir.path().join("half.exr");
    ::exr::prelude::write_rgba_file(&path, 3, 2, |x, y| {
        let v = ::exr::prelude::f16::from_f32(x as f32 - 0.5 * y as f32);
        (v, v, -v, ::exr::prelude::f16::ONE)
    })
    .unwrap();
    let image = Image::read_exr(&path).unwrap();
    assert_eq!(image.pixel(2, 1), [1.5, 1.5, -1.5]);
}

#[test]
fn layered_exr_uses_dotted_names_and_read_exr_explains_missing_channels() {
    let dir = temp_dir();
    let path = dir.path().join("grad.exr");
    let color = awkward_image();
    let mut grad = Image::new(7, 5);
    grad.set_pixel(3, 4, [-1.0, 2.0, -3.0]);
    Image::write_layers_exr(&path, &[("color", &color), ("grad.roughness", &grad)]).unwrap();

    let file = ::exr::prelude::read_first_flat_layer_from_file(&path).unwrap();
    let names: Vec<String> = file.layer_data.channel_data.list.iter().map(|c| c.name.to_string()).collect();
    assert_eq!(names, ["color.B", "color.G", "color.R", "grad.roughness.B", "grad.roughness.G", "grad.roughness.R"]);
    let grad_g = file.layer_data.channel_data.list.iter().find(|c| c.name == *"grad.roughness.G").unwrap();
    assert_eq!(grad_g.sample_data.values_as_f32().nth(4 * 7 + 3), Some(2.0));

    let err = Image::read_exr(&path).unwrap_err().to_string();
    assert!(err.contains("grad.exr") && err.contains("no 'R' channel") && err.contains("color.R"), "{err}");
}

#[test]
fn layered_exr_rejects_bad_layer_lists() {
    let dir = temp_dir();
    let path = dir.path().join("bad.exr");
    let a = Image::new(2, 2);
    let b = Image::new(3, 2);
    let cases: [(&[(&str, &Image)], &str); 4] = [
        (&[], "no layers"),
        (&[("x", &a), ("x", &a)], "two layers are named 'x'"),
        (&[("x", &a), ("y", &b)], "3×2"),
        (&[("grad.σ", &a)], "Latin-1"),
    ];
    for (layers, expected) in cases {
        let err = Image::write_layers_exr(&path, layers).unwrap_err().to_string();
        assert!(err.contains("bad.exr") && err.contains(expected), "{err}");
    }
    assert!(entries(dir.path()).is_empty());
}

#[test]
fn png_uses_the_exact_srgb_curve() {
    let dir = temp_dir();
    let path = dir.path().join("tone.png");
    let image = Image::from_rgb(
        2,
        2,
        vec![
            0.0,
            0.5,
            1.0, // exact points of the curve
            2.0,
            -1.0,
            f32::NAN, // out of range
            0.001,
            0.25,
            f32::INFINITY, // linear segment, power segment, +inf
            0.2,
            0.2,
            0.2, // grey
        ],
    )
    .unwrap();
    image.write_png(&path, 0.0).unwrap();
    let png = read_png(&path);
    assert_eq!(png.dimensions(), (2, 2));
    assert_eq!(png.get_pixel(0, 0).0, [0, 188, 255]);
    assert_eq!(png.get_pixel(1, 0).0, [255, 0, 0], ">1 clamps, negative and NaN are 0");
    // 0.001 is on the linear segment: 12.92 · 0.001 · 255 = 3.29; 0.25 → 0.5371 · 255 = 137.0.
    assert_eq!(png.get_pixel(0, 1).0, [3, 137, 255]);
    // 0.2 → 0.4845 · 255 = 123.55.
    assert_eq!(png.get_pixel(1, 1).0, [124; 3]);

    // Exposure +1 doubles: 0.25 → 0.5 → 188.
    image.write_png(&path, 1.0).unwrap();
    assert_eq!(read_png(&path).get_pixel(0, 1).0[1], 188);
    assert!(image.write_png(&path, f32::NAN).is_err());
}

#[test]
fn save_picks_the_format_by_extension() {
    let dir = temp_dir();
    let image = awkward_image();
    image.save(dir.path().join("x.EXR")).unwrap();
    assert_eq!(bits(&Image::read_exr(dir.path().join("x.EXR")).unwrap()), bits(&image));
    image.save(dir.path().join("x.Png")).unwrap();
    assert_eq!(read_png(&dir.path().join("x.Png")).dimensions(), (7, 5));
    for bad in ["x.jpg", "x"] {
        let err = image.save(dir.path().join(bad)).unwrap_err().to_string();
        assert!(err.contains(bad) && err.contains(".exr or .png"), "{err}");
    }
    assert_eq!(entries(dir.path()), ["x.EXR", "x.Png"]);
}

#[test]
fn diverging_map_stays_in_gamut() {
    for i in -1000..=1000 {
        let rgb = oklab_to_linear_srgb(diverging_oklab(f64::from(i) / 1000.0));
        assert!(rgb.iter().all(|&c| (-1e-6..=1.0 + 1e-6).contains(&c)), "t = {}: {rgb:?}", f64::from(i) / 1000.0);
    }
}

#[test]
fn signed_png_is_symmetric_and_white_at_zero() {
    let dir = temp_dir();
    let path = dir.path().join("grad.png");
    // Pixel sums: 0, ±0.25, ±0.5, ±1, ±4 (clamped), NaN.
    let sums = [0.0, 0.25, -0.25, 0.5, -0.5, 1.0, -1.0, 4.0, -4.0, f32::NAN];
    let data = sums.iter().flat_map(|&s| [s, 0.5 * s, -0.5 * s]).collect();
    let image = Image::from_rgb(sums.len() as u32, 1, data).unwrap();
    image.write_signed_png(&path, Some(1.0)).unwrap();
    let png = read_png(&path);
    let px = |i: u32| png.get_pixel(i, 0).0;

    assert!(px(0).iter().all(|&c| c >= 250), "0 is white: {:?}", px(0));
    assert_eq!(px(9), [0, 0, 0], "NaN is black");
    assert_eq!(px(7), px(5), "beyond the scale clamps");
    assert_eq!(px(8), px(6));
    for pair in [(1, 2), (3, 4), (5, 6)] {
        let (pos, neg) = (px(pair.0), px(pair.1));
        assert!(pos[0] > pos[2] && neg[2] > neg[0], "red for +, blue for -: {pos:?} {neg:?}");
        let lab_pos = linear_srgb_to_oklab(pos.map(srgb8_to_linear));
        let lab_neg = linear_srgb_to_oklab(neg.map(srgb8_to_linear));
        let chroma = |lab: [f64; 3]| lab[1].hypot(lab[2]);
        // One 8-bit step moves Oklab L and chroma by at most ~0.01.
        assert!((lab_pos[0] - lab_neg[0]).abs() < 0.01, "{lab_pos:?} {lab_neg:?}");
        assert!((chroma(lab_pos) - chroma(lab_neg)).abs() < 0.01, "{lab_pos:?} {lab_neg:?}");
    }
    // Stronger values are darker on both arms.
    let lightness = |i| linear_srgb_to_oklab(px(i).map(srgb8_to_linear))[0];
    assert!(lightness(0) > lightness(1) && lightness(1) > lightness(3));
    assert!(lightness(3) > lightness(5));

    assert!(image.write_signed_png(&path, Some(0.0)).is_err());
    assert!(image.write_signed_png(&path, Some(f32::INFINITY)).is_err());
}

#[test]
fn log_png_is_monotone_in_lightness_and_marks_nan() {
    // 1e-6 … 1 over six decades, one pixel each, plus zero, a negative value and NaN.
    let mut values: Vec<f32> = (0..=6).map(|k| 10f32.powi(k - 6)).collect();
    values.extend([0.0, -1.0, f32::NAN]);
    let image = Image::from_rgb(values.len() as u32, 1, values.iter().flat_map(|&v| [v; 3]).collect()).unwrap();
    let dir = temp_dir();
    let path = dir.path().join("log.png");
    image.write_log_png(&path, None, 6.0).unwrap();
    let png = read_png(&path);
    let lightness: Vec<f64> =
        (0..7).map(|x| linear_srgb_to_oklab(png.get_pixel(x, 0).0.map(srgb8_to_linear))[0]).collect();
    assert!(lightness.windows(2).all(|w| w[1] > w[0] + 0.05), "lightness must rise per decade: {lightness:?}");
    assert_eq!(png.get_pixel(7, 0), png.get_pixel(0, 0), "zero is drawn as the bottom of the scale");
    assert_eq!(png.get_pixel(8, 0), png.get_pixel(0, 0), "a negative value is drawn as the bottom");
    assert_eq!(png.get_pixel(9, 0).0, [255, 0, 255], "NaN is magenta");
    for t in (0..=100).map(|i| f64::from(i) / 100.0) {
        let rgb = oklab_to_linear_srgb(sequential_oklab(t));
        assert!(rgb.iter().all(|&c| (-1e-3..=1.0 + 1e-3).contains(&c)), "t = {t}: {rgb:?} is out of gamut");
    }
    assert!(image.write_log_png(&path, Some(0.0), 6.0).is_err());
    assert!(image.write_log_png(&path, None, f32::NAN).is_err());
}

#[test]
fn signed_scale_is_a_robust_percentile_and_never_zero() {
    // 200 pixels with sums 1..=200: the 99th percentile by nearest rank is 198.
    let data = (1..=200).flat_map(|i| [i as f32, 0.0, 0.0]).collect();
    assert_eq!(Image::from_rgb(200, 1, data).unwrap().signed_scale(), 198.0);
    // One firefly among zeros: the percentile is 0, so the maximum is used.
    let mut sparse = Image::new(1000, 1);
    sparse.set_pixel(3, 0, [0.0, -5.0, 0.0]);
    assert_eq!(sparse.signed_scale(), 5.0);
    assert_eq!(Image::new(4, 4).signed_scale(), 1.0);
    let nan = Image::from_rgb(1, 1, vec![f32::NAN; 3]).unwrap();
    assert_eq!(nan.signed_scale(), 1.0);
    // With no scale given, the automatic one is used and the write succeeds.
    let dir = temp_dir();
    Image::new(4, 4).write_signed_png(dir.path().join("zero.png"), None).unwrap();
}

#[test]
fn writes_are_atomic_and_errors_name_the_path() {
    let dir = temp_dir();
    let image = awkward_image();
    let missing = dir.path().join("no such dir");
    for name in ["a.exr", "a.png"] {
        let path = missing.join(name);
        let err = image.save(&path).unwrap_err();
        assert!(matches!(err, Error::Output { .. }) && err.to_string().contains("does not exist"), "{err:?}");
        assert!(err.to_string().contains(&*path.to_string_lossy()), "{err}");
    }
    let signed = image.write_signed_png(missing.join("s.png"), None).unwrap_err();
    assert!(signed.to_string().contains("no such dir"), "{signed}");
    assert!(!missing.exists());
    assert!(entries(dir.path()).is_empty(), "nothing is left behind");

    // A destination that is a directory is refused before anything is written.
    let target = dir.path().join("taken.exr");
    fs::create_dir(&target).unwrap();
    let err = image.write_exr(&target).unwrap_err().to_string();
    assert!(err.contains("taken.exr: is a directory"), "{err}");
    assert_eq!(entries(dir.path()), ["taken.exr"], "the temporary file is removed");
    assert!(target.is_dir());

    // An empty image cannot be written, and says so.
    let err = Image::new(0, 3).write_png(dir.path().join("e.png"), 0.0).unwrap_err();
    assert!(err.to_string().contains("0×3"), "{err}");
}

#[test]
fn reading_a_non_exr_file_names_it() {
    let dir = temp_dir();
    let path = dir.path().join("not-really.exr");
    Image::new(2, 2).write_png(path.with_extension("png"), 0.0).unwrap();
    fs::rename(path.with_extension("png"), &path).unwrap();
    let err = Image::read_exr(&path).unwrap_err();
    assert!(matches!(err, Error::Image { .. }), "{err:?}");
    let message = err.to_string();
    assert!(message.contains("not-really.exr") && message.contains("not a readable OpenEXR file"), "{message}");

    let missing = dir.path().join("missing.exr");
    let err = Image::read_exr(&missing).unwrap_err();
    assert!(matches!(err, Error::Io { .. }), "{err:?}");
    assert!(err.to_string().contains("missing.exr"), "{err}");
}
