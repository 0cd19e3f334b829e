//! `<spectrum value="λ:v, λ:v, …"/>`: a spectrum given as wavelength:value pairs, converted to
//! linear sRGB as Mitsuba 3.9.1's RGB variants convert it (`spectrum_list_to_srgb`).
//!
//! The spectrum is linear between its pairs and zero outside them; 1000 wavelengths evenly
//! spaced over [360, 830] nm (the ends included) that fall inside the pairs' range are summed,
//! weighted by the CIE 1931 2° colour matching functions (linear between 5 nm samples), by the
//! D65 illuminant for a reflectance-like property (Mitsuba's `d65`), times the step 0.47 nm and
//! Mitsuba's normalisation of Y; XYZ goes to linear sRGB by the standard matrix. Negative
//! channels are clamped to 0, and for a bounded property (a reflectance, every colour of
//! range [0, 1]) channels above 1 to 1, as Mitsuba does. An emitter's spectrum is integrated
//! without D65 and unbounded.

use glam::Vec3;

/// The wavelength range Mitsuba integrates over (nm).
const CIE_MIN: f32 = 360.0;
const CIE_MAX: f32 = 830.0;
/// Samples over that range.
const STEPS: u32 = 1000;
/// 1 / ∫ ȳ(λ) D65(λ) dλ with D65 as tabulated below (Mitsuba's `MI_CIE_Y_NORMALIZATION`).
const Y_NORMALIZATION: f32 = 0.009_367_659;

/// The CIE 1931 2° observer's x̄, ȳ, z̄ (CIE 015:2018) and the D65 illuminant (CIE, relative
/// spectral power times 0.0101012736, the scale Mitsuba 3 tabulates it at), every 5 nm from
/// 360 nm to 830 nm.
#[rustfmt::skip]
const CIE: [[f32; 4]; 95] = [
    [1.2990000e-04, 3.9170000e-06, 6.0610002e-04, 4.7110626e-01], // 360 nm
    [2.3210001e-04, 6.9650000e-06, 1.0860000e-03, 4.9863625e-01], // 365 nm
    [4.1489999e-04, 1.2390000e-05, 1.9460000e-03, 5.2616626e-01], // 370 nm
    [7.4160000e-04, 2.2020000e-05, 3.4860000e-03, 5.1549125e-01], // 375 nm
    [1.3680001e-03, 3.8999999e-05, 6.4500012e-03, 5.0481617e-01], // 380 nm
    [2.2360000e-03, 6.4000000e-05, 1.0549990e-02, 5.2841580e-01], // 385 nm
    [4.2429999e-03, 1.2000000e-04, 2.0050010e-02, 5.5201644e-01], // 390 nm
    [7.6500000e-03, 2.1699999e-04, 3.6210001e-02, 6.9397265e-01], // 395 nm
    [1.4310000e-02, 3.9599999e-04, 6.7850009e-02, 8.3592987e-01], // 400 nm
    [2.3189999e-02, 6.3999998e-04, 1.1020000e-01, 8.8002700e-01], // 405 nm
    [4.3510001e-02, 1.2100000e-03, 2.0739999e-01, 9.2412513e-01], // 410 nm
    [7.7629998e-02, 2.1800001e-03, 3.7130001e-01, 9.3395263e-01], // 415 nm
    [1.3438000e-01, 4.0000002e-03, 6.4560002e-01, 9.4378018e-01], // 420 nm
    [2.1477000e-01, 7.3000002e-03, 1.0390501e+00, 9.0969038e-01], // 425 nm
    [2.8389999e-01, 1.1600000e-02, 1.3856000e+00, 8.7560159e-01], // 430 nm
    [3.2850000e-01, 1.6840000e-02, 1.6229600e+00, 9.6743530e-01], // 435 nm
    [3.4828001e-01, 2.3000000e-02, 1.7470599e+00, 1.0592700e+00], // 440 nm
    [3.4806001e-01, 2.9800000e-02, 1.7826000e+00, 1.1205949e+00], // 445 nm
    [3.3620000e-01, 3.7999999e-02, 1.7721100e+00, 1.1819298e+00], // 450 nm
    [3.1869999e-01, 4.8000000e-02, 1.7441000e+00, 1.1859906e+00], // 455 nm
    [2.9080001e-01, 5.9999999e-02, 1.6691999e+00, 1.1900512e+00], // 460 nm
    [2.5110000e-01, 7.3899999e-02, 1.5281000e+00, 1.1751418e+00], // 465 nm
    [1.9536000e-01, 9.0980001e-02, 1.2876400e+00, 1.1602424e+00], // 470 nm
    [1.4210001e-01, 1.1260000e-01, 1.0419000e+00, 1.1656061e+00], // 475 nm
    [9.5640004e-02, 1.3902000e-01, 8.1295007e-01, 1.1709700e+00], // 480 nm
    [5.7950009e-02, 1.6930000e-01, 6.1619997e-01, 1.1350498e+00], // 485 nm
    [3.2010000e-02, 2.0802000e-01, 4.6518001e-01, 1.0991297e+00], // 490 nm
    [1.4700000e-02, 2.5860000e-01, 3.5330001e-01, 1.1018672e+00], // 495 nm
    [4.9000001e-03, 3.2300001e-01, 2.7200001e-01, 1.1046146e+00], // 500 nm
    [2.4000001e-03, 4.0730000e-01, 2.1230000e-01, 1.0967761e+00], // 505 nm
    [9.3000000e-03, 5.0300002e-01, 1.5820000e-01, 1.0889375e+00], // 510 nm
    [2.9100001e-02, 6.0820001e-01, 1.1170000e-01, 1.0737250e+00], // 515 nm
    [6.3270003e-02, 7.0999998e-01, 7.8249991e-02, 1.0585124e+00], // 520 nm
    [1.0960000e-01, 7.9320002e-01, 5.7250012e-02, 1.0731492e+00], // 525 nm
    [1.6550000e-01, 8.6199999e-01, 4.2160001e-02, 1.0877961e+00], // 530 nm
    [2.2574989e-01, 9.1485012e-01, 2.9840000e-02, 1.0712098e+00], // 535 nm
    [2.9040000e-01, 9.5400000e-01, 2.0300001e-02, 1.0546235e+00], // 540 nm
    [3.5969999e-01, 9.8030001e-01, 1.3400000e-02, 1.0528052e+00], // 545 nm
    [4.3344989e-01, 9.9495012e-01, 8.7499991e-03, 1.0509971e+00], // 550 nm
    [5.1205009e-01, 1.0000000e+00, 5.7499991e-03, 1.0305623e+00], // 555 nm
    [5.9450001e-01, 9.9500000e-01, 3.8999999e-03, 1.0101273e+00], // 560 nm
    [6.7839998e-01, 9.7860003e-01, 2.7499991e-03, 9.9161273e-01], // 565 nm
    [7.6209998e-01, 9.5200002e-01, 2.0999999e-03, 9.7309810e-01], // 570 nm
    [8.4249997e-01, 9.1540003e-01, 1.8000000e-03, 9.7033942e-01], // 575 nm
    [9.1630000e-01, 8.7000000e-01, 1.6500010e-03, 9.6758080e-01], // 580 nm
    [9.7860003e-01, 8.1629997e-01, 1.4000000e-03, 9.3170917e-01], // 585 nm
    [1.0263000e+00, 7.5700003e-01, 1.1000000e-03, 8.9583755e-01], // 590 nm
    [1.0567000e+00, 6.9489998e-01, 1.0000000e-03, 9.0250742e-01], // 595 nm
    [1.0622000e+00, 6.3099998e-01, 7.9999998e-04, 9.0917730e-01], // 600 nm
    [1.0456001e+00, 5.6680000e-01, 6.0000003e-04, 9.0712059e-01], // 605 nm
    [1.0026000e+00, 5.0300002e-01, 3.4000000e-04, 9.0506500e-01], // 610 nm
    [9.3839997e-01, 4.4119999e-01, 2.3999999e-04, 8.9546680e-01], // 615 nm
    [8.5444993e-01, 3.8100001e-01, 1.9000001e-04, 8.8586855e-01], // 620 nm
    [7.5139999e-01, 3.2100001e-01, 9.9999997e-05, 8.6359423e-01], // 625 nm
    [6.4240003e-01, 2.6499999e-01, 4.9999991e-05, 8.4132093e-01], // 630 nm
    [5.4189998e-01, 2.1699999e-01, 2.9999999e-05, 8.4339470e-01], // 635 nm
    [4.4790000e-01, 1.7500000e-01, 1.9999999e-05, 8.4546858e-01], // 640 nm
    [3.6080000e-01, 1.3820000e-01, 9.9999997e-06, 8.2692057e-01], // 645 nm
    [2.8349999e-01, 1.0700000e-01, 0.0000000e+00, 8.0837262e-01], // 650 nm
    [2.1870001e-01, 8.1600003e-02, 0.0000000e+00, 8.0932111e-01], // 655 nm
    [1.6490000e-01, 6.1000001e-02, 0.0000000e+00, 8.1026959e-01], // 660 nm
    [1.2120000e-01, 4.4580001e-02, 0.0000000e+00, 8.2069010e-01], // 665 nm
    [8.7399997e-02, 3.2000002e-02, 0.0000000e+00, 8.3111060e-01], // 670 nm
    [6.3600004e-02, 2.3200000e-02, 0.0000000e+00, 8.1094033e-01], // 675 nm
    [4.6769999e-02, 1.7000001e-02, 0.0000000e+00, 7.9077017e-01], // 680 nm
    [3.2900002e-02, 1.1920000e-02, 0.0000000e+00, 7.4752152e-01], // 685 nm
    [2.2700001e-02, 8.2099997e-03, 0.0000000e+00, 7.0427394e-01], // 690 nm
    [1.5840000e-02, 5.7230000e-03, 0.0000000e+00, 7.1380854e-01], // 695 nm
    [1.1359160e-02, 4.1020000e-03, 0.0000000e+00, 7.2334313e-01], // 700 nm
    [8.1109162e-03, 2.9290000e-03, 0.0000000e+00, 7.3718083e-01], // 705 nm
    [5.7903458e-03, 2.0910001e-03, 0.0000000e+00, 7.5101960e-01], // 710 nm
    [4.1094571e-03, 1.4840000e-03, 0.0000000e+00, 6.8664926e-01], // 715 nm
    [2.8993271e-03, 1.0470001e-03, 0.0000000e+00, 6.2227887e-01], // 720 nm
    [2.0491900e-03, 7.3999999e-04, 0.0000000e+00, 6.6410619e-01], // 725 nm
    [1.4399710e-03, 5.2000000e-04, 0.0000000e+00, 7.0593357e-01], // 730 nm
    [9.9994929e-04, 3.6110001e-04, 0.0000000e+00, 7.3220390e-01], // 735 nm
    [6.9007860e-04, 2.4920001e-04, 0.0000000e+00, 7.5847429e-01], // 740 nm
    [4.7602129e-04, 1.7190000e-04, 0.0000000e+00, 7.0042026e-01], // 745 nm
    [3.3230110e-04, 1.2000000e-04, 0.0000000e+00, 6.4236730e-01], // 750 nm
    [2.3482610e-04, 8.4799998e-05, 0.0000000e+00, 5.5562460e-01], // 755 nm
    [1.6615049e-04, 5.9999998e-05, 0.0000000e+00, 4.6888295e-01], // 760 nm
    [1.1741300e-04, 4.2399999e-05, 0.0000000e+00, 5.7185131e-01], // 765 nm
    [8.3075269e-05, 2.9999999e-05, 0.0000000e+00, 6.7481959e-01], // 770 nm
    [5.8706519e-05, 2.1200000e-05, 0.0000000e+00, 6.5753335e-01], // 775 nm
    [4.1509938e-05, 1.4990000e-05, 0.0000000e+00, 6.4024705e-01], // 780 nm
    [2.9353259e-05, 1.0600000e-05, 0.0000000e+00, 6.4489967e-01], // 785 nm
    [2.0673830e-05, 7.4657000e-06, 0.0000000e+00, 6.4955229e-01], // 790 nm
    [1.4559770e-05, 5.2577998e-06, 0.0000000e+00, 6.2504560e-01], // 795 nm
    [1.0253980e-05, 3.7028999e-06, 0.0000000e+00, 6.0053992e-01], // 800 nm
    [7.2214561e-06, 2.6078001e-06, 0.0000000e+00, 5.6269550e-01], // 805 nm
    [5.0858680e-06, 1.8365999e-06, 0.0000000e+00, 5.2485210e-01], // 810 nm
    [3.5816520e-06, 1.2934000e-06, 0.0000000e+00, 5.5253762e-01], // 815 nm
    [2.5225249e-06, 9.1093000e-07, 0.0000000e+00, 5.8022326e-01], // 820 nm
    [1.7765090e-06, 6.4152999e-07, 0.0000000e+00, 5.9472764e-01], // 825 nm
    [1.2511410e-06, 4.5181000e-07, 0.0000000e+00, 6.0923308e-01], // 830 nm
];

/// XYZ → linear sRGB (D65 white), rows.
const XYZ_TO_SRGB: [[f32; 3]; 3] =
    [[3.240_479, -1.537_150, -0.498_535], [-0.969_256, 1.875_991, 0.041_556], [0.055_648, -0.204_043, 1.057_311]];

/// The table's four columns at wavelength `w` in [360, 830], linear between samples.
fn cie_at(w: f32) -> [f32; 4] {
    let t = ((w - CIE_MIN) / 5.0).clamp(0.0, (CIE.len() - 1) as f32);
    let i = (t as usize).min(CIE.len() - 2);
    let f = t - i as f32;
    let (a, b) = (CIE[i], CIE[i + 1]);
    [0, 1, 2, 3].map(|c| a[c] + f * (b[c] - a[c]))
}

/// The linear sRGB of a spectrum with increasing `wavelengths` (nm) and `values` (at least two
/// pairs), for a reflectance-like property (`d65`) or an emitter's radiance (not), clamped to
/// [0, 1] when `bounded` (else only below, at 0).
pub(super) fn to_srgb(wavelengths: &[f32], values: &[f32], bounded: bool, d65: bool) -> Vec3 {
    let (first, last) = (wavelengths[0], wavelengths[wavelengths.len() - 1]);
    let mut xyz = Vec3::ZERO;
    for i in 0..STEPS {
        let w = CIE_MIN + (i as f32 / (STEPS - 1) as f32) * (CIE_MAX - CIE_MIN);
        if w < first || w > last {
            continue;
        }
        // The last pair whose wavelength is ≤ w, at most the second to last.
        let k = wavelengths.partition_point(|&x| x <= w).saturating_sub(1).min(wavelengths.len() - 2);
        let (w0, w1, v0, v1) = (wavelengths[k], wavelengths[k + 1], values[k], values[k + 1]);
        let v = ((w - w1) * v0 + (w0 - w) * v1) / (w0 - w1);
        let c = cie_at(w);
        xyz += Vec3::new(c[0], c[1], c[2]) * v * if d65 { c[3] } else { 1.0 };
    }
    xyz *= (CIE_MAX - CIE_MIN) / STEPS as f32 * Y_NORMALIZATION;
    let rgb = Vec3::from(XYZ_TO_SRGB.map(|row| Vec3::from(row).dot(xyz)));
    if bounded { rgb.clamp(Vec3::ZERO, Vec3::ONE) } else { rgb.max(Vec3::ZERO) }
}

/// Parses `λ:v, λ:v, …` (separated by commas or spaces): at least two pairs, wavelengths
/// finite and strictly increasing, values finite.
pub(super) fn parse_pairs(text: &str) -> Result<(Vec<f32>, Vec<f32>), String> {
    let mut wavelengths = Vec::new();
    let mut values = Vec::new();
    for token in text.split([',', ' ', '\t', '\n', '\r']).filter(|t| !t.is_empty()) {
        let (w, v) = token.split_once(':').ok_or_else(|| format!("'{token}' is not a wavelength:value pair"))?;
        let parse = |s: &str| s.trim().parse::<f32>().ok().filter(|x| x.is_finite());
        let (Some(w), Some(v)) = (parse(w), parse(v)) else {
            return Err(format!("'{token}' is not a pair of finite numbers"));
        };
        if wavelengths.last().is_some_and(|&last| w <= last) {
            return Err(format!("wavelengths must increase ({w} nm after {} nm)", wavelengths[wavelengths.len() - 1]));
        }
        wavelengths.push(w);
        values.push(v);
    }
    if wavelengths.len() < 2 {
        return Err("a spectrum needs at least two wavelength:value pairs".into());
    }
    Ok((wavelengths, values))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `mi.spectrum_list_to_srgb(wavelengths, values, bounded, d65)` in Mitsuba 3.9.1 (scalar_rgb)
    /// for (bounded, d65) = (true, true), (false, true), (false, false).
    #[test]
    fn spectra_convert_as_mitsuba_converts_them() {
        let cases: [(&[f32], &[f32], [[f32; 3]; 3]); 4] = [
            (
                &[400.0, 500.0, 600.0, 700.0],
                &[0.2, 0.5, 0.7, 0.3],
                [
                    [0.652_419, 0.599_145_2, 0.329_929_65],
                    [0.652_419, 0.599_145_2, 0.329_929_65],
                    [0.771_546_5, 0.573_037_4, 0.292_026_3],
                ],
            ),
            (
                &[450.0, 550.0, 650.0],
                &[1.5, 0.2, 0.9],
                [
                    [0.448_304_83, 0.476_735_6, 0.729_760_8],
                    [0.448_304_83, 0.476_735_6, 0.729_760_8],
                    [0.569_422_4, 0.449_019_22, 0.616_673_35],
                ],
            ),
            (
                &[380.0, 780.0],
                &[0.5, 0.5],
                [
                    [0.499_465_73, 0.499_455_48, 0.499_272_47],
                    [0.499_465_73, 0.499_455_48, 0.499_272_47],
                    [0.602_391_6, 0.474_151_6, 0.454_381_9],
                ],
            ),
            (
                &[500.0, 520.0],
                &[2.0, 3.0],
                [
                    [0.0, 0.496_252_86, 0.031_503_093],
                    [0.0, 0.496_252_86, 0.031_503_093],
                    [0.0, 0.459_195_38, 0.028_593_045],
                ],
            ),
        ];
        for (w, v, expected) in cases {
            for ((bounded, d65), e) in [(true, true), (false, true), (false, false)].into_iter().zip(expected) {
                let got = to_srgb(w, v, bounded, d65);
                assert!(
                    got.abs_diff_eq(Vec3::from(e), 2e-6),
                    "{w:?} {v:?} bounded {bounded} d65 {d65}: {got} vs {e:?}"
                );
            }
        }
    }

    #[test]
    fn malformed_pairs_are_refused() {
        assert_eq!(parse_pairs("400:0.1, 500:0.2").unwrap(), (vec![400.0, 500.0], vec![0.1, 0.2]));
        assert_eq!(parse_pairs("400:0.1 500:0.2\n600:1").unwrap().0, [400.0, 500.0, 600.0]);
        assert_eq!(parse_pairs("400:0.1").unwrap_err(), "a spectrum needs at least two wavelength:value pairs");
        assert_eq!(parse_pairs("500:0.1, 400:0.2").unwrap_err(), "wavelengths must increase (400 nm after 500 nm)");
        assert_eq!(parse_pairs("400:x, 500:1").unwrap_err(), "'400:x' is not a pair of finite numbers");
        assert_eq!(parse_pairs("400, 500:1").unwrap_err(), "'400' is not a wavelength:value pair");
    }
}
