//! Water optics per Jerlov type: `I_c = J_c exp(-b_c d) + B_c (1 - exp(-b_c d))`, `d` the ray length.
//!
//! Attenuation `b_c = -ln N_c` from the per-metre transmittance `N_c` of UWCNN (Li, Anwar & Porikli,
//! Pattern Recognition 2020), see `research/synthetic-scenes.md`. The veiling colours `B_c` are our
//! choice: deep blue for clear ocean turning green-brown for turbid coastal water, as in footage.

use fme_edge::sequence::WaterMeta;

/// Jerlov water types, clear ocean `I` to turbid coastal `9C`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum WaterType {
    /// Clear open ocean.
    #[value(name = "I")]
    I,
    /// Open ocean.
    #[value(name = "II")]
    II,
    /// Open ocean, more productive.
    #[value(name = "III")]
    III,
    /// Clearest coastal water.
    #[value(name = "1C")]
    C1,
    /// Coastal water (default: a typical sea cage).
    #[value(name = "3C")]
    C3,
    /// Coastal water, turbid.
    #[value(name = "5C")]
    C5,
    /// Coastal water, very turbid.
    #[value(name = "7C")]
    C7,
    /// Turbid coastal water or pond.
    #[value(name = "9C")]
    C9,
}

impl WaterType {
    /// Name as written in `meta.json`.
    pub fn name(self) -> &'static str {
        match self {
            Self::I => "I",
            Self::II => "II",
            Self::III => "III",
            Self::C1 => "1C",
            Self::C3 => "3C",
            Self::C5 => "5C",
            Self::C7 => "7C",
            Self::C9 => "9C",
        }
    }

    /// Per-metre transmittance `N_c` (R, G, B), UWCNN table.
    pub fn transmittance(self) -> [f64; 3] {
        match self {
            Self::I => [0.85, 0.961, 0.982],
            Self::II => [0.80, 0.925, 0.94],
            Self::III => [0.75, 0.885, 0.89],
            Self::C1 => [0.75, 0.885, 0.875],
            Self::C3 => [0.71, 0.82, 0.80],
            Self::C5 => [0.67, 0.73, 0.67],
            Self::C7 => [0.62, 0.61, 0.50],
            Self::C9 => [0.55, 0.46, 0.29],
        }
    }

    /// Attenuation `b_c = -ln N_c` per metre (R, G, B).
    pub fn attenuation(self) -> [f64; 3] {
        self.transmittance().map(|n| -n.ln())
    }

    /// Veiling light `B_c` (R, G, B) in `[0, 1]`.
    pub fn veil(self) -> [f64; 3] {
        match self {
            Self::I => [0.05, 0.30, 0.52],
            Self::II => [0.06, 0.33, 0.50],
            Self::III => [0.07, 0.36, 0.48],
            Self::C1 => [0.08, 0.38, 0.45],
            Self::C3 => [0.10, 0.40, 0.40],
            Self::C5 => [0.15, 0.42, 0.33],
            Self::C7 => [0.22, 0.40, 0.25],
            Self::C9 => [0.30, 0.38, 0.20],
        }
    }

    /// Diffuse attenuation of daylight with depth below the surface, per metre (mean of `b_c`).
    pub fn light_decay(self) -> f64 {
        let b = self.attenuation();
        (b[0] + b[1] + b[2]) / 3.0
    }

    /// The `meta.json` block.
    pub fn meta(self) -> WaterMeta {
        WaterMeta { kind: self.name().into(), attenuation_per_m: self.attenuation(), backscatter: self.veil() }
    }
}
