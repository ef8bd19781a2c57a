//! Helpers shared by the perception tests (tiny configurations).

#![allow(dead_code)]

use workcell_procnet::{CellKind, ProcNetConfig};
use workcell_render::Class;

/// A 3-layer network small enough for debug-build tests.
pub fn tiny(cell: CellKind) -> ProcNetConfig {
    ProcNetConfig {
        input_size: 16,
        repr_channels: vec![4, 6, 8],
        input_channels: vec![3, 4, 6],
        cell,
        classes: vec![Class::Forearm, Class::Robot],
        // The paper's decoder; `reference.rs` has a case with the full-resolution one.
        decoder_full_resolution: false,
        ..ProcNetConfig::cpu()
    }
}

/// The deterministic test frames of `bench/procnet.py reference` (same formula), frame `t`,
/// batch entry `b`: `0.5 + 0.5 sin(0.37 x + 0.23 y + 1.1 c + 0.5 t + 0.7 b)`.
pub fn reference_frame(t: usize, b: usize, size: usize) -> Vec<f32> {
    let mut v = Vec::with_capacity(3 * size * size);
    for c in 0..3 {
        for y in 0..size {
            for x in 0..size {
                let a = 0.37 * x as f64
                    + 0.23 * y as f64
                    + 1.1 * c as f64
                    + 0.5 * t as f64
                    + 0.7 * b as f64;
                v.push((0.5 + 0.5 * a.sin()) as f32);
            }
        }
    }
    v
}
