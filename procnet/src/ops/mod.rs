//! Backend operations of our own (burn backend extensions), where ProcNet's hot spots are
//! faster as one operation than composed from burn's: the group normalisation with its
//! closed-form gradient, and flex's "same" convolution and upsampling for inference.

// burn 0.22 marks LibTorch deprecated in favour of its CubeCL backends; it is still the fastest
// CPU training backend here (backend.rs), and the extension macro names it in generated code.
#![allow(deprecated)]

mod conv;
mod group_norm;
mod upsample;

pub use conv::{ConvSameBackend, conv_same};
pub use group_norm::{GroupNormBackend, GroupNormKernels, NORM_EPS, group_norm};
pub use upsample::{Upsample2Backend, upsample2};
