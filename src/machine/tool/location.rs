//! Location errors (ISO 230-1, position-independent): orientation errors of
//! linear axes, position/orientation/zero-angle errors of rotary axes and the
//! location of the spindle axis. Also the rules for which names an axis may
//! carry.

use nalgebra::{Matrix4, Vector3};

use super::geometry::{small_angle, translation};

/// Letters of error directions and axes, slot order.
pub(crate) const LETTERS: [char; 6] = ['X', 'Y', 'Z', 'A', 'B', 'C'];

/// Constant location errors of one axis.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LocationErrors {
    /// Position offset of a rotary axis' line (mm), components along x, y, z;
    /// the component along the axis itself is always zero. Zero for linear axes.
    pub offset_mm: Vector3<f64>,
    /// Small orientation errors about x, y, z (rad); the component about the
    /// axis' own direction is always zero (see `zero_rad`).
    pub angles_rad: Vector3<f64>,
    /// Zero-angle error of a rotary axis (rad); zero for linear axes.
    pub zero_rad: f64,
}

impl LocationErrors {
    /// True when all location errors are zero.
    pub fn is_zero(&self) -> bool {
        self.offset_mm == Vector3::zeros()
            && self.angles_rad == Vector3::zeros()
            && self.zero_rad == 0.0
    }

    /// The orientation-error HTM (rotation only).
    pub fn orientation_htm(&self) -> Matrix4<f64> {
        small_angle(&Vector3::zeros(), &self.angles_rad)
    }
}

/// Location errors of the spindle axis: offset of the tool axis (x, y, mm)
/// and its tilt about x and y (rad), applied at the gauge line.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SpindleErrors {
    /// EX0S, EY0S offset of the tool axis, mm (z component zero).
    pub offset_mm: Vector3<f64>,
    /// EA0S, EB0S tilt of the tool axis about x and y, rad (z component zero).
    pub angles_rad: Vector3<f64>,
}

impl SpindleErrors {
    /// True when all spindle errors are zero.
    pub fn is_zero(&self) -> bool {
        self.offset_mm == Vector3::zeros() && self.angles_rad == Vector3::zeros()
    }

    /// Spindle location HTM: offset, then tilt about the gauge-line point.
    pub fn htm(&self) -> Matrix4<f64> {
        translation(&self.offset_mm) * small_angle(&Vector3::zeros(), &self.angles_rad)
    }
}

/// What a location-error key sets.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum LocationKey {
    /// Offset along direction 0..3 (mm).
    Offset(usize),
    /// Orientation about direction 0..3 (µrad in the file).
    Angle(usize),
    /// Zero-angle error (µrad in the file).
    Zero,
}

/// Interprets a location-error key of axis `slot` (0..6), or says which keys
/// are allowed.
pub(crate) fn location_key(slot: usize, key: &str) -> Result<LocationKey, String> {
    let axis = LETTERS.get(slot).copied().unwrap_or('?');
    let mut allowed: Vec<(String, LocationKey)> = Vec::new();
    if slot < 3 {
        for r in 0..3 {
            if r != slot {
                allowed.push((
                    format!("E{}0{axis}_urad", LETTERS[r + 3]),
                    LocationKey::Angle(r),
                ));
            }
        }
    } else {
        let own = slot - 3;
        allowed.push((format!("E{axis}0{axis}_urad"), LocationKey::Zero));
        for (t, letter) in LETTERS.iter().take(3).enumerate() {
            if t != own {
                allowed.push((format!("E{letter}0{axis}_mm"), LocationKey::Offset(t)));
            }
        }
        for r in 0..3 {
            if r != own {
                allowed.push((
                    format!("E{}0{axis}_urad", LETTERS[r + 3]),
                    LocationKey::Angle(r),
                ));
            }
        }
    }
    match allowed.iter().find(|(n, _)| n == key) {
        Some((_, k)) => Ok(*k),
        None => Err(format!(
            "unknown location error `{key}` for the {axis} axis (allowed: {})",
            allowed
                .iter()
                .map(|(n, _)| n.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        )),
    }
}

/// Interprets a spindle location-error key.
pub(crate) fn spindle_key(key: &str) -> Result<LocationKey, String> {
    match key {
        "EX0S_mm" => Ok(LocationKey::Offset(0)),
        "EY0S_mm" => Ok(LocationKey::Offset(1)),
        "EA0S_urad" => Ok(LocationKey::Angle(0)),
        "EB0S_urad" => Ok(LocationKey::Angle(1)),
        _ => Err(format!(
            "unknown spindle location error `{key}` (allowed: EX0S_mm, EY0S_mm, EA0S_urad, EB0S_urad)"
        )),
    }
}

/// Interprets a component-error key of axis `slot`: returns the error
/// direction 0..6 (X Y Z translations in µm, A B C rotations in µrad).
pub(crate) fn component_key(slot: usize, key: &str) -> Result<usize, String> {
    let axis = LETTERS.get(slot).copied().unwrap_or('?');
    for (i, l) in LETTERS.iter().enumerate() {
        let unit = if i < 3 { "um" } else { "urad" };
        if key == format!("E{l}{axis}_{unit}") {
            return Ok(i);
        }
    }
    Err(format!(
        "unknown component error `{key}` for the {axis} axis (allowed: E{{X,Y,Z}}{axis}_um, E{{A,B,C}}{axis}_urad)"
    ))
}
