//! Fixed-length number arrays that reject the wrong length.
//!
//! serde reads `[f64; N]` by taking the first `N` elements of a sequence;
//! the TOML deserializer does not complain about the rest, so
//! `eye_mm = [0, -13, 8, 5]` would load as `[0, -13, 8]`. Every fixed-size
//! array of a scenario goes through [`Exact`] instead (with the
//! `deserialize_with` helpers below), which reads the whole sequence and
//! names the expected length when it differs.

use serde::de::{Deserialize, Deserializer, Error as _};

/// `N` numbers, exactly.
struct Exact<const N: usize>([f64; N]);

impl<'de, const N: usize> Deserialize<'de> for Exact<N> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let v = Vec::<f64>::deserialize(d)?;
        let len = v.len();
        v.try_into().map(Exact).map_err(|_| {
            D::Error::invalid_length(len, &format!("an array of {N} numbers").as_str())
        })
    }
}

/// `[f64; N]`.
pub fn exact<'de, D: Deserializer<'de>, const N: usize>(d: D) -> Result<[f64; N], D::Error> {
    Exact::<N>::deserialize(d).map(|e| e.0)
}

/// `Option<[f64; N]>`.
pub fn exact_opt<'de, D: Deserializer<'de>, const N: usize>(
    d: D,
) -> Result<Option<[f64; N]>, D::Error> {
    Option::<Exact<N>>::deserialize(d).map(|o| o.map(|e| e.0))
}

/// `Vec<[f64; N]>` (rows of a table such as keyframes).
pub fn exact_rows<'de, D: Deserializer<'de>, const N: usize>(
    d: D,
) -> Result<Vec<[f64; N]>, D::Error> {
    Vec::<Exact<N>>::deserialize(d).map(|v| v.into_iter().map(|e| e.0).collect())
}

/// `Option<Vec<[f64; N]>>`.
pub fn exact_rows_opt<'de, D: Deserializer<'de>, const N: usize>(
    d: D,
) -> Result<Option<Vec<[f64; N]>>, D::Error> {
    Option::<Vec<Exact<N>>>::deserialize(d).map(|o| o.map(|v| v.into_iter().map(|e| e.0).collect()))
}
