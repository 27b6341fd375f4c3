//! Ray sets: photons recorded where they arrived on a surface (`[[detectors]] type = "rays"`),
//! written as `rays_<name>.npy`, and emitted again by a light with `shape = { type = "rays",
//! file }`, so a luminaire's near field can be simulated once and reused.
//!
//! The file is a NumPy array of float64, shape [N, 8], C order, little endian: rows x, y, z (the
//! scene's unit), dx, dy, dz (any non-zero length; normalised on reading), wavelength_nm (0 when
//! the ray was recorded in grey transport, which carries none) and power_w (≥ 0). A light emits
//! its rays in proportion to their power: a photon picks ray k with probability P_k/ΣP and leaves
//! from its point along its direction, carrying the light's share of the power like any photon,
//! so the emitted flux through every part of phase space equals the set's.

use std::path::Path;

use glam::DVec3;

use crate::error::InputError;

/// One ray of a set, in the scene file's coordinates and unit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub position: DVec3,
    pub direction: DVec3,
    /// nm; 0 when the set carries no wavelengths.
    pub lambda_nm: f64,
    pub power_w: f64,
}

#[derive(Clone, Debug)]
pub struct RaySet {
    pub rays: Vec<Ray>,
    /// Σ power_w.
    pub total_w: f64,
    /// Whether the rays carry wavelengths (all do, or none).
    pub has_wavelengths: bool,
}

/// Most rays a file may hold: 10⁸ (6.4 GB of float64 rows, which `MAX_INPUT_BYTES` caps further).
pub const MAX_RAYS: u64 = 100_000_000;

/// A ray-set detector (`[[detectors]] type = "rays"`): records every arrival on a surface.
#[derive(Clone, Debug)]
pub struct RayDetector {
    pub name: String,
    pub surface: usize,
    /// Most arrivals it may record in one run (`max_rays`): a run past it stops with an error.
    pub max_rays: u64,
}

pub fn read(path: &Path) -> Result<RaySet, InputError> {
    let bytes = crate::error::read_input(path, "ray set")?;
    parse(path, &bytes)
}

/// Reads a .npy ray set; errors name the byte offset of what is wrong.
pub fn parse(path: &Path, bytes: &[u8]) -> Result<RaySet, InputError> {
    let err = |at: usize, m: String| InputError::new(path, "", None, format!("byte {at}: {m}"));
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err(err(0, "not a NumPy .npy file (no \\x93NUMPY magic)".into()));
    }
    let (major, minor) = (bytes[6], bytes[7]);
    let (header_len, start): (usize, usize) = match major {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize, 12),
        _ => return Err(err(6, format!("unsupported .npy version {major}.{minor} (1.0, 2.0 and 3.0 are read)"))),
    };
    let data_at = start.checked_add(header_len).filter(|&e| e <= bytes.len());
    let Some(data_at) = data_at else {
        return Err(err(8, format!("the header of {header_len} bytes runs past the end of the file")));
    };
    let header =
        std::str::from_utf8(&bytes[start..data_at]).map_err(|_| err(start, "the header is not text".into()))?;
    let field = |key: &str| -> Option<&str> {
        let at = header.find(&format!("'{key}'"))?;
        let rest = header[at + key.len() + 2..].trim_start().strip_prefix(':')?.trim_start();
        Some(rest)
    };
    let descr = field("descr").ok_or_else(|| err(start, "the header has no 'descr'".into()))?;
    if !(descr.starts_with("'<f8'") || descr.starts_with("'float64'")) {
        let shown: String = descr.chars().take(12).collect();
        return Err(err(start, format!("the array must be little-endian float64 ('<f8'), found {shown}")));
    }
    let fortran = field("fortran_order").ok_or_else(|| err(start, "the header has no 'fortran_order'".into()))?;
    if !fortran.starts_with("False") {
        return Err(err(start, "the array must be in C order (fortran_order False)".into()));
    }
    let shape = field("shape").ok_or_else(|| err(start, "the header has no 'shape'".into()))?;
    let dims: Option<Vec<u64>> = shape
        .strip_prefix('(')
        .and_then(|s| s.split(')').next())
        .map(|s| s.split(',').map(str::trim).filter(|d| !d.is_empty()).map(|d| d.parse::<u64>().ok()).collect())
        .and_then(|v: Vec<Option<u64>>| v.into_iter().collect());
    let n = match dims.as_deref() {
        Some([n, 8]) => *n,
        _ => {
            let shown: String = shape.chars().take_while(|&c| c != ')').chain([')']).collect();
            return Err(err(
                start,
                format!("the array's shape must be (N, 8): x, y, z, dx, dy, dz, wavelength_nm, power_w; found {shown}"),
            ));
        }
    };
    if n == 0 {
        return Err(err(start, "the ray set holds no rays".into()));
    }
    if n > MAX_RAYS {
        return Err(err(start, format!("{n} rays are more than the {MAX_RAYS} photon reads")));
    }
    let want = n as usize * 64;
    if bytes.len() - data_at != want {
        return Err(err(
            data_at,
            format!("{n} rows of 8 float64 need {want} bytes of data, the file has {}", bytes.len() - data_at),
        ));
    }
    let mut rays = Vec::with_capacity(n as usize);
    let mut total_w = 0.0;
    let mut with_lambda = 0u64;
    for (k, row) in bytes[data_at..].chunks_exact(64).enumerate() {
        let v: [f64; 8] = std::array::from_fn(|i| f64::from_le_bytes(row[8 * i..8 * i + 8].try_into().unwrap()));
        let at = data_at + 64 * k;
        if let Some(i) = v.iter().position(|x| !x.is_finite()) {
            return Err(err(at + 8 * i, format!("row {k}: value {i} is not finite")));
        }
        let direction = DVec3::new(v[3], v[4], v[5]);
        let len = direction.length();
        if !(len > 0.0 && len.is_finite()) {
            return Err(err(at + 24, format!("row {k}: the direction (dx, dy, dz) is zero")));
        }
        if v[6] < 0.0 {
            return Err(err(at + 48, format!("row {k}: the wavelength must be >= 0 (0: none), found {}", v[6])));
        }
        if !(v[7] >= 0.0 && v[7] <= crate::scene::load::MAX_POWER_W) {
            return Err(err(
                at + 56,
                format!(
                    "row {k}: the power must be within 0 to {:e} W, found {}",
                    crate::scene::load::MAX_POWER_W,
                    v[7]
                ),
            ));
        }
        with_lambda += (v[6] > 0.0) as u64;
        total_w += v[7];
        rays.push(Ray {
            position: DVec3::new(v[0], v[1], v[2]),
            direction: direction / len,
            lambda_nm: v[6],
            power_w: v[7],
        });
    }
    if with_lambda != 0 && with_lambda != n {
        return Err(err(
            data_at,
            format!("{with_lambda} of {n} rays carry a wavelength and the rest 0: all or none must"),
        ));
    }
    if !(total_w > 0.0 && total_w <= crate::scene::load::MAX_POWER_W) {
        return Err(err(
            data_at,
            format!(
                "the rays' total power must be positive and at most {:e} W, found {total_w}",
                crate::scene::load::MAX_POWER_W
            ),
        ));
    }
    Ok(RaySet { rays, total_w, has_wavelengths: with_lambda == n })
}
