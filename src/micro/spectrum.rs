//! Radially averaged height power spectra, per octave of spatial frequency.
//!
//! The map's heights (µm, mean removed) go through a 2D FFT; each
//! frequency `f = √((k_x/W)² + (k_y/H)²)` cycles per texel below the
//! Nyquist circle (f ≤ ½) contributes `|F(k)|² / (W·H)` to its octave.
//! Octaves run down from Nyquist: `(¼, ½]`, `(⅛, ¼]`, … while they hold
//! frequencies of the map (f ≥ 1/min(W, H)). An octave's power is the mean
//! over its frequencies: a density, comparable between maps of different
//! sizes at the same texel. The FFT treats the map as periodic, which a
//! wrapping map is; a clamped map's edges add a little broadband power.

use rustfft::num_complex::Complex;
use rustfft::FftPlanner;

use super::map::DisplacementMap;

/// One octave of a spectrum.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Octave {
    /// Lower frequency bound (cycles per µm, exclusive).
    pub low_per_um: f64,
    /// Upper frequency bound (cycles per µm, inclusive).
    pub high_per_um: f64,
    /// Mean `|F|²/(W·H)` over the octave's frequencies (µm²).
    pub power: f64,
    /// Frequencies in the octave.
    pub count: usize,
}

/// The octave spectrum of `map`, lowest octave first.
pub fn octaves(map: &DisplacementMap) -> Vec<Octave> {
    let (w, h) = (map.width, map.height);
    if w < 2 || h < 2 {
        return Vec::new();
    }
    let unit = map.height_unit_um;
    let mean = map.data.iter().map(|&v| v as f64).sum::<f64>() / (w * h) as f64;
    let mut data: Vec<Complex<f64>> = map
        .data
        .iter()
        .map(|&v| Complex::new((v as f64 - mean) * unit, 0.0))
        .collect();
    let mut planner = FftPlanner::new();
    let rows = planner.plan_fft_forward(w);
    for row in data.chunks_mut(w) {
        rows.process(row);
    }
    let cols = planner.plan_fft_forward(h);
    let mut column = vec![Complex::new(0.0, 0.0); h];
    for i in 0..w {
        for j in 0..h {
            column[j] = data[j * w + i];
        }
        cols.process(&mut column);
        for j in 0..h {
            data[j * w + i] = column[j];
        }
    }
    let lowest = 1.0 / w.min(h) as f64;
    let mut bands = Vec::new();
    let mut high = 0.5;
    while high / 2.0 >= lowest * 0.999 {
        bands.push((high / 2.0, high, 0.0f64, 0usize));
        high /= 2.0;
    }
    let norm = (w * h) as f64;
    let signed = |k: usize, n: usize| {
        if k <= n / 2 {
            k as f64
        } else {
            k as f64 - n as f64
        }
    };
    for j in 0..h {
        let fy = signed(j, h) / h as f64;
        for i in 0..w {
            let fx = signed(i, w) / w as f64;
            let f = (fx * fx + fy * fy).sqrt();
            if f == 0.0 || f > 0.5 {
                continue;
            }
            if let Some(b) = bands.iter_mut().find(|b| f > b.0 && f <= b.1) {
                b.2 += data[j * w + i].norm_sqr() / norm;
                b.3 += 1;
            }
        }
    }
    let t = map.texel_um;
    bands
        .into_iter()
        .rev()
        .filter(|b| b.3 > 0)
        .map(|(lo, hi, p, n)| Octave {
            low_per_um: lo / t,
            high_per_um: hi / t,
            power: p / n as f64,
            count: n,
        })
        .collect()
}

/// Largest relative difference `|P_a/P_b − 1|` between two spectra of maps
/// with the same texel over the octaves whose lower bound is at least
/// `from_per_um` and upper bound at most `to_per_um`; with the octaves
/// compared. None when no octave falls in the band.
pub fn band_difference(
    a: &[Octave],
    b: &[Octave],
    from_per_um: f64,
    to_per_um: f64,
) -> Option<(f64, Vec<(Octave, Octave)>)> {
    let mut pairs = Vec::new();
    for oa in a {
        if oa.low_per_um < from_per_um * 0.999 || oa.high_per_um > to_per_um * 1.001 {
            continue;
        }
        if let Some(ob) = b
            .iter()
            .find(|ob| (ob.high_per_um / oa.high_per_um - 1.0).abs() < 1e-6)
        {
            pairs.push((*oa, *ob));
        }
    }
    let worst = pairs
        .iter()
        .map(|(x, y)| (x.power / y.power - 1.0).abs())
        .fold(None, |m: Option<f64>, d| Some(m.map_or(d, |m| m.max(d))))?;
    Some((worst, pairs))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::micro::Edge;

    #[test]
    fn a_sinusoid_puts_its_power_in_its_octave() {
        // 8 cycles over 64 texels: f = 1/8 cycles/texel, at the top of the
        // octave (1/16, 1/8]. Amplitude 2 µm: |F|² = (2·N/2)² at ±k, so
        // the octave's mean is 2 · (N·A/2)²/N / count, N = 64².
        let n = 64;
        let m = DisplacementMap::from_fn(n, n, 2.0, Edge::Wrap, |i, _| {
            2.0 * (2.0 * std::f32::consts::PI * 8.0 * i as f32 / n as f32).sin()
        });
        let oct = octaves(&m);
        let hit = oct
            .iter()
            .find(|o| (o.high_per_um - 0.125 / 2.0).abs() < 1e-12)
            .unwrap();
        let total = (n * n) as f64;
        let expected = 2.0 * (total * 2.0 / 2.0).powi(2) / total / hit.count as f64;
        assert!(
            (hit.power / expected - 1.0).abs() < 1e-5,
            "{} vs {expected}",
            hit.power
        );
        for o in oct.iter().filter(|o| o.high_per_um != hit.high_per_um) {
            assert!(o.power < 1e-12 * hit.power, "{o:?}");
        }
        // Bounds in cycles/µm with 2 µm texels.
        assert_eq!(oct.last().unwrap().high_per_um, 0.25);
        assert_eq!(oct.first().unwrap().low_per_um, 1.0 / 64.0 / 2.0);
    }

    #[test]
    fn band_difference_compares_matching_octaves() {
        let n = 32;
        let a =
            DisplacementMap::from_fn(n, n, 1.0, Edge::Wrap, |i, j| ((i * 7 + j * 3) % 5) as f32);
        let twice = a.with_data(a.data.iter().map(|v| v * 2.0).collect());
        let (worst, pairs) = band_difference(&octaves(&twice), &octaves(&a), 0.0, 1.0).unwrap();
        assert!((worst - 3.0).abs() < 1e-9, "power ×4");
        assert!(!pairs.is_empty());
        assert!(band_difference(&octaves(&a), &octaves(&a), 10.0, 20.0).is_none());
    }
}
