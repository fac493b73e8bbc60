//! Where BC, T-REX and PPO's learned-reward inference compute: the CPU (the default, and
//! the only device of a machine whose libtorch sees no CUDA device) or the first CUDA GPU.
//!
//! The device changes a stage's bytes (another order of floating-point sums), so a stage
//! that computes on the GPU carries `device: cuda` in its parameters, and so in its key.
//! A CPU stage's parameters carry no device field at all: keys computed before the GPU
//! path existed stay valid.
use crate::error::{Error, Result};

/// The device a stage computes on; part of its definition.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Device {
    #[default]
    Cpu,
    /// The first CUDA device, through libtorch.
    Cuda,
}

impl Device {
    pub fn is_cpu(&self) -> bool {
        *self == Device::Cpu
    }

    pub fn name(self) -> &'static str {
        match self {
            Device::Cpu => "cpu",
            Device::Cuda => "cuda",
        }
    }

    pub fn tch(self) -> tch::Device {
        match self {
            Device::Cpu => tch::Device::Cpu,
            Device::Cuda => tch::Device::Cuda(0),
        }
    }

    /// Fails, saying how to fix it, where this machine cannot compute on the device.
    pub fn ensure_available(self) -> Result<()> {
        if self == Device::Cuda && !cuda_available() {
            return Err(Error::Invalid(
                "device cuda was asked for (`--device`, or the pipeline's `device`), but libtorch sees no CUDA \
                 device on this machine; run where there is one, or use `--device cpu` (whose stages have other keys)"
                    .into(),
            ));
        }
        Ok(())
    }
}

/// What the user asks for: `auto` takes the GPU where libtorch sees one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum DeviceChoice {
    #[default]
    Auto,
    Cpu,
    Cuda,
}

impl DeviceChoice {
    /// The device, resolved on this machine. An explicit `cuda` is kept even where there is
    /// no GPU, so that a login node can plan and submit jobs for GPU nodes; the stage fails
    /// with [`Device::ensure_available`] if it runs somewhere without one.
    pub fn resolve(self) -> Device {
        match self {
            DeviceChoice::Cpu => Device::Cpu,
            DeviceChoice::Cuda => Device::Cuda,
            DeviceChoice::Auto if cuda_available() => Device::Cuda,
            DeviceChoice::Auto => Device::Cpu,
        }
    }
}

/// Whether libtorch can compute on a CUDA device here. libtorch's CUDA backend lives in
/// `libtorch_cuda.so`, which the linker drops from the binary (idrex calls nothing in it
/// directly), and loading it costs every process about half a second and 400 MB: so it is
/// loaded here, once, and only where an NVIDIA driver is present. Without that load
/// `tch::Cuda::is_available()` is false even on a GPU machine.
fn cuda_available() -> bool {
    static AVAILABLE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *AVAILABLE.get_or_init(|| {
        let driver = ["/dev/nvidiactl", "/proc/driver/nvidia"].iter().any(|p| std::path::Path::new(p).exists());
        driver && load_torch_cuda() && tch::Cuda::is_available()
    })
}

/// Loads libtorch's CUDA backend (its static initialisers register it with libtorch),
/// found through the binary's run path, beside `libtorch_cpu.so`.
#[allow(unsafe_code)] // dlopen
fn load_torch_cuda() -> bool {
    use std::os::raw::{c_char, c_int, c_void};
    unsafe extern "C" {
        fn dlopen(filename: *const c_char, flags: c_int) -> *mut c_void;
    }
    const RTLD_NOW: c_int = 2;
    const RTLD_GLOBAL: c_int = 0x100;
    // SAFETY: a NUL-terminated name; the library stays loaded for the life of the process.
    let handle = unsafe { dlopen(c"libtorch_cuda.so".as_ptr(), RTLD_NOW | RTLD_GLOBAL) };
    if handle.is_null() {
        tracing::warn!("an NVIDIA driver is present but libtorch_cuda.so did not load: computing on the CPU");
    }
    !handle.is_null()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resolves_and_checks() {
        assert_eq!(DeviceChoice::Cpu.resolve(), Device::Cpu);
        assert_eq!(DeviceChoice::Cuda.resolve(), Device::Cuda);
        let auto = DeviceChoice::Auto.resolve();
        assert_eq!(auto == Device::Cuda, cuda_available());
        assert!(Device::Cpu.ensure_available().is_ok());
        let cuda = Device::Cuda.ensure_available();
        assert_eq!(cuda.is_ok(), cuda_available());
        if let Err(e) = cuda {
            assert!(e.to_string().contains("--device cpu"), "{e}");
        }
    }

    /// The CUDA backend loads wherever the linked libtorch has one: on a GPU machine only the
    /// driver check stands between it and `auto` choosing the GPU.
    #[test]
    fn loads_libtorchs_cuda_backend_where_it_has_one() {
        let maps = std::fs::read_to_string("/proc/self/maps").unwrap();
        let cpu = maps.split_whitespace().find(|w| w.ends_with("/libtorch_cpu.so")).expect("libtorch_cpu.so is mapped");
        let has_cuda = std::path::Path::new(cpu).with_file_name("libtorch_cuda.so").exists();
        assert_eq!(load_torch_cuda(), has_cuda, "libtorch at {cpu}");
        if has_cuda {
            let maps = std::fs::read_to_string("/proc/self/maps").unwrap();
            assert!(maps.contains("/libtorch_cuda.so"));
        }
    }
}
