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
    [1.299e-4, 3.917e-6, 6.061e-4, 4.7110626e-1], // 360 nm
    [2.321e-4, 6.965e-6, 1.086e-3, 4.9863625e-1], // 365 nm
    [4.149e-4, 1.239e-5, 1.946e-3, 5.2616626e-1], // 370 nm
    [7.416e-4, 2.202e-5, 3.486e-3, 5.1549125e-1], // 375 nm
    [1.368e-3, 3.9e-5, 6.450001e-3, 5.048162e-1], // 380 nm
    [2.236e-3, 6.4e-5, 1.054999e-2, 5.284158e-1], // 385 nm
    [4.243e-3, 1.2e-4, 2.005001e-2, 5.5201644e-1], // 390 nm
    [7.65e-3, 2.17e-4, 3.621e-2, 6.9397265e-1], // 395 nm
    [1.431e-2, 3.96e-4, 6.785001e-2, 8.359299e-1], // 400 nm
    [2.319e-2, 6.4e-4, 1.102e-1, 8.80027e-1], // 405 nm
    [4.351e-2, 1.21e-3, 2.074e-1, 9.2412513e-1], // 410 nm
    [7.763e-2, 2.18e-3, 3.713e-1, 9.339526e-1], // 415 nm
    [1.3438e-1, 4.0e-3, 6.456e-1, 9.437802e-1], // 420 nm
    [2.1477e-1, 7.3e-3, 1.0390501e+0, 9.096904e-1], // 425 nm
    [2.839e-1, 1.16e-2, 1.3856e+0, 8.756016e-1], // 430 nm
    [3.285e-1, 1.684e-2, 1.62296e+0, 9.674353e-1], // 435 nm
    [3.4828e-1, 2.3e-2, 1.74706e+0, 1.05927e+0], // 440 nm
    [3.4806e-1, 2.98e-2, 1.7826e+0, 1.1205949e+0], // 445 nm
    [3.362e-1, 3.8e-2, 1.77211e+0, 1.1819298e+0], // 450 nm
    [3.187e-1, 4.8e-2, 1.7441e+0, 1.1859906e+0], // 455 nm
    [2.908e-1, 6.0e-2, 1.6692e+0, 1.1900512e+0], // 460 nm
    [2.511e-1, 7.39e-2, 1.5281e+0, 1.1751418e+0], // 465 nm
    [1.9536e-1, 9.098e-2, 1.28764e+0, 1.1602424e+0], // 470 nm
    [1.421e-1, 1.126e-1, 1.0419e+0, 1.1656061e+0], // 475 nm
    [9.564e-2, 1.3902e-1, 8.129501e-1, 1.17097e+0], // 480 nm
    [5.795001e-2, 1.693e-1, 6.162e-1, 1.1350498e+0], // 485 nm
    [3.201e-2, 2.0802e-1, 4.6518e-1, 1.0991297e+0], // 490 nm
    [1.47e-2, 2.586e-1, 3.533e-1, 1.1018672e+0], // 495 nm
    [4.9e-3, 3.23e-1, 2.72e-1, 1.1046146e+0], // 500 nm
    [2.4e-3, 4.073e-1, 2.123e-1, 1.0967761e+0], // 505 nm
    [9.3e-3, 5.03e-1, 1.582e-1, 1.0889375e+0], // 510 nm
    [2.91e-2, 6.082e-1, 1.117e-1, 1.073725e+0], // 515 nm
    [6.327e-2, 7.1e-1, 7.824999e-2, 1.0585124e+0], // 520 nm
    [1.096e-1, 7.932e-1, 5.725001e-2, 1.0731492e+0], // 525 nm
    [1.655e-1, 8.62e-1, 4.216e-2, 1.0877961e+0], // 530 nm
    [2.257499e-1, 9.148501e-1, 2.984e-2, 1.0712098e+0], // 535 nm
    [2.904e-1, 9.54e-1, 2.03e-2, 1.0546235e+0], // 540 nm
    [3.597e-1, 9.803e-1, 1.34e-2, 1.0528052e+0], // 545 nm
    [4.334499e-1, 9.949501e-1, 8.749999e-3, 1.0509971e+0], // 550 nm
    [5.120501e-1, 1.0e+0, 5.749999e-3, 1.0305623e+0], // 555 nm
    [5.945e-1, 9.95e-1, 3.9e-3, 1.0101273e+0], // 560 nm
    [6.784e-1, 9.786e-1, 2.749999e-3, 9.9161273e-1], // 565 nm
    [7.621e-1, 9.52e-1, 2.1e-3, 9.730981e-1], // 570 nm
    [8.425e-1, 9.154e-1, 1.8e-3, 9.703394e-1], // 575 nm
    [9.163e-1, 8.7e-1, 1.650001e-3, 9.675808e-1], // 580 nm
    [9.786e-1, 8.163e-1, 1.4e-3, 9.317092e-1], // 585 nm
    [1.0263e+0, 7.57e-1, 1.1e-3, 8.9583755e-1], // 590 nm
    [1.0567e+0, 6.949e-1, 1.0e-3, 9.025074e-1], // 595 nm
    [1.0622e+0, 6.31e-1, 8.0e-4, 9.091773e-1], // 600 nm
    [1.0456e+0, 5.668e-1, 6.0e-4, 9.071206e-1], // 605 nm
    [1.0026e+0, 5.03e-1, 3.4e-4, 9.05065e-1], // 610 nm
    [9.384e-1, 4.412e-1, 2.4e-4, 8.954668e-1], // 615 nm
    [8.544499e-1, 3.81e-1, 1.9e-4, 8.8586855e-1], // 620 nm
    [7.514e-1, 3.21e-1, 1.0e-4, 8.6359423e-1], // 625 nm
    [6.424e-1, 2.65e-1, 4.999999e-5, 8.4132093e-1], // 630 nm
    [5.419e-1, 2.17e-1, 3.0e-5, 8.433947e-1], // 635 nm
    [4.479e-1, 1.75e-1, 2.0e-5, 8.454686e-1], // 640 nm
    [3.608e-1, 1.382e-1, 1.0e-5, 8.2692057e-1], // 645 nm
    [2.835e-1, 1.07e-1, 0.0e+0, 8.083726e-1], // 650 nm
    [2.187e-1, 8.16e-2, 0.0e+0, 8.093211e-1], // 655 nm
    [1.649e-1, 6.1e-2, 0.0e+0, 8.102696e-1], // 660 nm
    [1.212e-1, 4.458e-2, 0.0e+0, 8.206901e-1], // 665 nm
    [8.74e-2, 3.2e-2, 0.0e+0, 8.311106e-1], // 670 nm
    [6.36e-2, 2.32e-2, 0.0e+0, 8.109403e-1], // 675 nm
    [4.677e-2, 1.7e-2, 0.0e+0, 7.907702e-1], // 680 nm
    [3.29e-2, 1.192e-2, 0.0e+0, 7.475215e-1], // 685 nm
    [2.27e-2, 8.21e-3, 0.0e+0, 7.0427394e-1], // 690 nm
    [1.584e-2, 5.723e-3, 0.0e+0, 7.1380854e-1], // 695 nm
    [1.135916e-2, 4.102e-3, 0.0e+0, 7.2334313e-1], // 700 nm
    [8.110916e-3, 2.929e-3, 0.0e+0, 7.371808e-1], // 705 nm
    [5.790346e-3, 2.091e-3, 0.0e+0, 7.510196e-1], // 710 nm
    [4.109457e-3, 1.484e-3, 0.0e+0, 6.8664926e-1], // 715 nm
    [2.899327e-3, 1.047e-3, 0.0e+0, 6.2227887e-1], // 720 nm
    [2.04919e-3, 7.4e-4, 0.0e+0, 6.641062e-1], // 725 nm
    [1.439971e-3, 5.2e-4, 0.0e+0, 7.059336e-1], // 730 nm
    [9.999493e-4, 3.611e-4, 0.0e+0, 7.322039e-1], // 735 nm
    [6.900786e-4, 2.492e-4, 0.0e+0, 7.584743e-1], // 740 nm
    [4.760213e-4, 1.719e-4, 0.0e+0, 7.0042026e-1], // 745 nm
    [3.323011e-4, 1.2e-4, 0.0e+0, 6.423673e-1], // 750 nm
    [2.348261e-4, 8.48e-5, 0.0e+0, 5.556246e-1], // 755 nm
    [1.661505e-4, 6.0e-5, 0.0e+0, 4.6888295e-1], // 760 nm
    [1.17413e-4, 4.24e-5, 0.0e+0, 5.718513e-1], // 765 nm
    [8.307527e-5, 3.0e-5, 0.0e+0, 6.748196e-1], // 770 nm
    [5.870652e-5, 2.12e-5, 0.0e+0, 6.5753335e-1], // 775 nm
    [4.150994e-5, 1.499e-5, 0.0e+0, 6.4024705e-1], // 780 nm
    [2.935326e-5, 1.06e-5, 0.0e+0, 6.4489967e-1], // 785 nm
    [2.067383e-5, 7.4657e-6, 0.0e+0, 6.495523e-1], // 790 nm
    [1.455977e-5, 5.2578e-6, 0.0e+0, 6.250456e-1], // 795 nm
    [1.025398e-5, 3.7029e-6, 0.0e+0, 6.005399e-1], // 800 nm
    [7.221456e-6, 2.6078e-6, 0.0e+0, 5.626955e-1], // 805 nm
    [5.085868e-6, 1.8366e-6, 0.0e+0, 5.248521e-1], // 810 nm
    [3.581652e-6, 1.2934e-6, 0.0e+0, 5.525376e-1], // 815 nm
    [2.522525e-6, 9.1093e-7, 0.0e+0, 5.8022326e-1], // 820 nm
    [1.776509e-6, 6.4153e-7, 0.0e+0, 5.9472764e-1], // 825 nm
    [1.251141e-6, 4.5181e-7, 0.0e+0, 6.092331e-1], // 830 nm
];

/// XYZ → linear sRGB (D65 white), rows.
const XYZ_TO_SRGB: [[f32; 3]; 3] =
    [[3.240_479, -1.537_15, -0.498_535], [-0.969_256, 1.875_991, 0.041_556], [0.055_648, -0.204_043, 1.057_311]];

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
        type Case<'a> = (&'a [f32], &'a [f32], [[f32; 3]; 3]);
        let cases: [Case; 4] = [
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
