//! Backend selection. Burn picks the backend from the device: the Flex CPU backend by default,
//! a GPU through wgpu when the crate is built with the `wgpu` feature and asked for one.

use burn::tensor::Device;

/// Which backend to run on.
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Default,
    clap::ValueEnum,
    serde::Serialize,
    serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Backend {
    /// Burn's Flex CPU backend (SIMD, all cores through rayon).
    #[default]
    Cpu,
    /// The default wgpu adapter (Vulkan, Metal or DX12); needs the `wgpu` feature.
    Wgpu,
}

/// The backend was not compiled in.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("this build has no wgpu backend; rebuild with `--features wgpu`")]
pub struct BackendUnavailable;

impl Backend {
    /// An inference device (no autodiff).
    pub fn device(self) -> Result<Device, BackendUnavailable> {
        match self {
            Backend::Cpu => Ok(Device::flex()),
            #[cfg(feature = "wgpu")]
            Backend::Wgpu => Ok(Device::wgpu(burn::tensor::DeviceKind::DefaultDevice)),
            #[cfg(not(feature = "wgpu"))]
            Backend::Wgpu => Err(BackendUnavailable),
        }
    }
}
