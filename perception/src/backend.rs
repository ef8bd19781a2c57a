//! Which backend runs the network; the model code is the same for all.

use burn::tensor::Device;
use serde::{Deserialize, Serialize};

use crate::error::{PerceptionError, Result};

/// A compute backend, chosen at run time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Backend {
    /// burn's pure-Rust CPU backend (always available).
    #[default]
    Flex,
    /// LibTorch on the CPU (cargo feature `tch`).
    Tch,
    /// The default GPU through wgpu (Vulkan, Metal or DX12; cargo feature `gpu`).
    Gpu,
}

impl Backend {
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Backend::Flex => "flex",
            Backend::Tch => "tch",
            Backend::Gpu => "gpu",
        }
    }

    /// Parses `flex` or `tch`.
    pub fn parse(name: &str) -> Result<Self> {
        match name {
            "flex" => Ok(Backend::Flex),
            "tch" => Ok(Backend::Tch),
            "gpu" => Ok(Backend::Gpu),
            other => Err(PerceptionError::Backend {
                name: other.into(),
                message: "unknown backend (known: flex, tch, gpu)".into(),
            }),
        }
    }

    /// Backends compiled into this build.
    #[must_use]
    pub fn available() -> Vec<Backend> {
        let mut v = vec![Backend::Flex];
        if cfg!(feature = "tch") {
            v.push(Backend::Tch);
        }
        if cfg!(feature = "gpu") {
            v.push(Backend::Gpu);
        }
        v
    }

    /// The device of this backend (inference; call `.autodiff()` on it to train).
    pub fn device(self) -> Result<Device> {
        match self {
            Backend::Flex => Ok(Device::flex()),
            // burn 0.22 marks LibTorch deprecated in favour of its CubeCL backends; it is still
            // the fastest CPU training backend here (docs/perception.md).
            #[cfg(feature = "tch")]
            #[allow(deprecated)]
            Backend::Tch => Ok(Device::libtorch()),
            #[cfg(not(feature = "tch"))]
            Backend::Tch => Err(PerceptionError::Backend {
                name: "tch".into(),
                message: "not compiled in: build with `--features tch` (see the README)".into(),
            }),
            #[cfg(feature = "gpu")]
            Backend::Gpu => Ok(Device::wgpu(burn::tensor::DeviceKind::DefaultDevice)),
            #[cfg(not(feature = "gpu"))]
            Backend::Gpu => Err(PerceptionError::Backend {
                name: "gpu".into(),
                message: "not compiled in: build with `--features gpu` (see the README)".into(),
            }),
        }
    }
}

/// Sets the number of CPU threads of both backends (rayon for flex, LibTorch's intra-op
/// pool for tch). Call it once, before the first tensor operation.
pub fn set_threads(threads: usize) {
    let threads = threads.max(1);
    // The global pool can only be built once; a second call keeps the first size.
    let _ = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build_global();
    #[cfg(feature = "tch")]
    tch_threads(threads);
}

#[cfg(feature = "tch")]
fn tch_threads(threads: usize) {
    let threads = i32::try_from(threads).unwrap_or(i32::MAX);
    tch::set_num_threads(threads);
    tch::set_num_interop_threads(1);
}
