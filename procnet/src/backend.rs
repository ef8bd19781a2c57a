//! Which backend runs the network; the model code is the same for all.

use std::sync::OnceLock;
use std::sync::atomic::{AtomicUsize, Ordering};

use burn::tensor::Device;
use serde::{Deserialize, Serialize};

use crate::error::{ProcNetError, Result};

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
            other => Err(ProcNetError::Backend {
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
            // the fastest CPU training backend here (experiments/perception.md).
            #[cfg(feature = "tch")]
            #[allow(deprecated)]
            Backend::Tch => Ok(Device::libtorch()),
            #[cfg(not(feature = "tch"))]
            Backend::Tch => Err(ProcNetError::Backend {
                name: "tch".into(),
                message: "not compiled in: build with `--features tch` (see the README)".into(),
            }),
            #[cfg(feature = "gpu")]
            Backend::Gpu => Ok(Device::wgpu(burn::tensor::DeviceKind::DefaultDevice)),
            #[cfg(not(feature = "gpu"))]
            Backend::Gpu => Err(ProcNetError::Backend {
                name: "gpu".into(),
                message: "not compiled in: build with `--features gpu` (see the README)".into(),
            }),
        }
    }
}

/// The most CPU threads a run may ask for (`--threads`, a training recipe's `threads`): far
/// above the cores of any machine the project runs on, and low enough that the thread pools
/// start at once.
pub const MAX_THREADS: usize = 256;

/// Sets the number of CPU threads of both backends (rayon for flex, LibTorch's intra-op
/// pool for tch, and the threads of a camera stream's forward pass on flex,
/// [`on_stream_threads`]). Call it once, before the first tensor operation.
pub fn set_threads(threads: usize) {
    let threads = threads.max(1);
    STREAM_THREADS.store(threads, Ordering::Relaxed);
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

/// Threads of [`on_stream_threads`]'s pool; 0 until [`set_threads`]: as many as rayon's
/// global pool.
static STREAM_THREADS: AtomicUsize = AtomicUsize::new(0);
static STREAM_POOL: OnceLock<Option<rayon::ThreadPool>> = OnceLock::new();

/// Runs `f`, a camera stream's forward pass on flex, on threads that flush subnormal floats to
/// zero, and returns its result.
///
/// A stream's recurrent state decays towards zero between frames that excite it, and after a
/// few hundred frames much of it is subnormal: each operation on a subnormal float takes a
/// microcode assist. Measured on the cell's camera (`workcell bench-perception --depth
/// --frames 300`, two threads): the network took 37.4 ms a frame with subnormals, 16.0 ms with
/// them flushed (20.3 ms flushing them in the convolutions alone). Values below 1.2e-38 change
/// nothing a mask shows.
///
/// The flush is a per-thread setting of the CPU (x86-64's MXCSR flags FTZ and DAZ); it is set
/// only on a pool of this module's own threads, so the caller's threads (the physics, the
/// fit) keep IEEE arithmetic. Elsewhere than on x86-64 the pool keeps subnormals. A pool that
/// cannot start runs `f` on the caller's thread.
///
/// The caller waits for `f` blocked, not inside rayon: a caller that is itself a rayon worker
/// (the evaluation runs its episodes on rayon's pool) would otherwise run other jobs of its
/// pool while it waits (rayon's `install` from a foreign pool does), nesting whole episodes on
/// its stack. A panic in `f` is resumed in the caller.
pub fn on_stream_threads<R: Send + 'static>(f: impl FnOnce() -> R + Send + 'static) -> R {
    let pool = STREAM_POOL.get_or_init(|| {
        let threads = match STREAM_THREADS.load(Ordering::Relaxed) {
            0 => rayon::current_num_threads(),
            n => n,
        };
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|i| format!("procnet-stream-{i}"))
            .start_handler(|_| flush_subnormals_on_this_thread())
            .build()
            .ok()
    });
    let Some(pool) = pool else {
        return f();
    };
    let (tx, rx) = std::sync::mpsc::sync_channel(1);
    pool.spawn(move || {
        // The receiver waits for this send; it cannot have gone away.
        let _ = tx.send(std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)));
    });
    match rx.recv() {
        Ok(Ok(result)) => result,
        Ok(Err(panic)) => std::panic::resume_unwind(panic),
        // The pool lives as long as the process and runs every job spawned on it.
        Err(_) => unreachable!("the stream pool dropped a job"),
    }
}

/// Sets this thread's CPU to flush subnormal results to zero and read subnormal inputs as
/// zero (x86-64; a no-op elsewhere).
fn flush_subnormals_on_this_thread() {
    #[cfg(target_arch = "x86_64")]
    {
        /// MXCSR's flush-to-zero (bit 15) and denormals-are-zero (bit 6) flags.
        const FTZ_DAZ: u32 = 0x8040;
        let mut csr: u32 = 0;
        // SAFETY: `stmxcsr` stores this thread's MXCSR into `csr`, `ldmxcsr` loads it back
        // with the two subnormal flags set: that changes only how this thread's SSE/AVX
        // arithmetic treats subnormals. Both read or write just the 4 bytes of `csr`.
        unsafe {
            std::arch::asm!(
                "stmxcsr [{}]",
                in(reg) &raw mut csr,
                options(nostack, preserves_flags)
            );
            csr |= FTZ_DAZ;
            std::arch::asm!(
                "ldmxcsr [{}]",
                in(reg) &raw const csr,
                options(nostack, preserves_flags, readonly)
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::hint::black_box;

    /// 1e-30 * 1e-10 = 1e-40 is below f32's smallest normal (1.18e-38): a subnormal in IEEE
    /// arithmetic, 0 where subnormals are flushed.
    fn tiny_product() -> f32 {
        black_box(1e-30f32) * black_box(1e-10f32)
    }

    #[test]
    fn stream_threads_flush_subnormals_and_the_caller_keeps_them() {
        assert!(tiny_product().is_subnormal());
        let (product, subnormal_input_doubled) =
            on_stream_threads(|| (tiny_product(), black_box(1e-40f32) * black_box(2.0f32)));
        if cfg!(target_arch = "x86_64") {
            assert_eq!(product, 0.0);
            // Denormals-are-zero: a subnormal operand reads as 0.
            assert_eq!(subnormal_input_doubled, 0.0);
        } else {
            assert!(product.is_subnormal());
        }
        // The caller's thread is left as it was.
        assert!(tiny_product().is_subnormal());
    }

    /// A caller that is a rayon worker waits for the stream blocked: it runs no other job of
    /// its pool meanwhile (each job here would see the other as running on its thread).
    #[test]
    fn a_rayon_worker_waiting_for_the_stream_runs_nothing_else() {
        use std::sync::atomic::AtomicBool;
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("pool");
        let busy = AtomicBool::new(false);
        let nested = AtomicBool::new(false);
        pool.scope(|s| {
            for _ in 0..4 {
                s.spawn(|_| {
                    if busy.swap(true, Ordering::SeqCst) {
                        nested.store(true, Ordering::SeqCst);
                    }
                    on_stream_threads(|| std::thread::sleep(std::time::Duration::from_millis(5)));
                    busy.store(false, Ordering::SeqCst);
                });
            }
        });
        assert!(!nested.load(Ordering::SeqCst));
    }

    #[test]
    fn a_panic_on_the_stream_threads_reaches_the_caller() {
        let caught = std::panic::catch_unwind(|| on_stream_threads(|| panic!("in the stream")));
        let message = caught.expect_err("the panic comes back");
        assert_eq!(message.downcast_ref::<&str>(), Some(&"in the stream"));
    }
}
