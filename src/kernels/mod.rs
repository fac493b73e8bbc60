//! The kernels: every computation whose bits idrex fixes on any x86-64 processor, and all of
//! the `unsafe` that makes them fast. The matrix products ([`gemm`] in f32, [`bf16`] with
//! bf16 factors) and their x86 micro-kernels, the elementwise passes' AVX-512 builds
//! (`vectorised!`), register transposes ([`transpose_rows`]), 64-byte-aligned buffers
//! ([`Buf`]) and the per-thread denormal flush ([`FlushDenormals`]). The networks in
//! [`crate::nn`] and the learners in [`crate::algo`] call these; nothing here knows of a
//! network.
use std::ops::Range;

pub mod bf16;
pub mod gemm;

/// Records that a test checked less than its name says because this processor lacks `what`:
/// one line on stderr past the capture, and one in the skip ledger (`IDREX_SKIP_LEDGER`, which
/// `./dev test` counts and `.ci/run` checks against the skips it declares).
#[cfg(test)]
pub(crate) fn narrowed(test: &str, what: &str) {
    use std::io::Write;
    let line = format!("test {test} ... SKIPPED (in part): this processor has no {what}\n");
    let _ = std::io::stderr().lock().write_all(line.as_bytes());
    if let Some(path) = std::env::var_os("IDREX_SKIP_LEDGER")
        && let Ok(mut f) = std::fs::OpenOptions::new().create(true).append(true).open(path)
    {
        let _ = f.write_all(line.as_bytes());
    }
}

/// Elementwise passes, each compiled twice, for AVX-512 (where the active [`gemm::Kernel`] is
/// AVX-512) and for the baseline x86-64 the crate targets. Both give the same bits: the
/// passes are independent per element or sum over rows in row order, and Rust neither
/// reassociates nor fuses multiply-adds.
macro_rules! vectorised {
    ($(#[$doc:meta])* fn $name:ident($($arg:ident: $ty:ty),*) $body:block) => {
        $(#[$doc])*
        #[allow(unsafe_code)] // expands where it is used: the one AVX-512 call below
        pub fn $name($($arg: $ty),*) {
            #[inline(always)]
            fn body($($arg: $ty),*) $body
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx512f")]
                unsafe fn wide($($arg: $ty),*) {
                    body($($arg),*)
                }
                if $crate::kernels::gemm::Kernel::active() == $crate::kernels::gemm::Kernel::Avx512 {
                    // SAFETY: the variant is active only where the CPU has AVX-512F.
                    return unsafe { wide($($arg),*) };
                }
            }
            body($($arg),*)
        }
    };
}

pub(crate) use vectorised;

/// A growable f32 buffer whose start is 64-byte aligned.
#[derive(Clone, Default)]
pub struct Buf {
    blocks: Vec<Block>,
    len: usize,
}

#[derive(Clone, Copy)]
#[repr(C, align(64))]
struct Block([f32; 16]);

impl Buf {
    pub fn zeros(len: usize) -> Self {
        let mut b = Buf::default();
        b.resize(len);
        b
    }

    /// Sets the length; new elements are zero, kept ones keep their values.
    pub fn resize(&mut self, len: usize) {
        self.blocks.resize(len.div_ceil(16), Block([0.0; 16]));
        self.len = len;
    }
}

impl std::ops::Deref for Buf {
    type Target = [f32];
    fn deref(&self) -> &[f32] {
        // SAFETY: the blocks are contiguous f32s, at least `len` of them.
        unsafe { std::slice::from_raw_parts(self.blocks.as_ptr().cast::<f32>(), self.len) }
    }
}

impl std::ops::DerefMut for Buf {
    fn deref_mut(&mut self) -> &mut [f32] {
        // SAFETY: as above, uniquely borrowed.
        unsafe { std::slice::from_raw_parts_mut(self.blocks.as_mut_ptr().cast::<f32>(), self.len) }
    }
}

/// Rows `rows` of the transpose (`inp x out`) of the `out x inp` row-major `w`, written to
/// `dst` (those rows, `out` apart): `dst[(i - rows.start) * out + o] = w[o * inp + i]`.
/// Register transposes of 8 x 8 blocks where the processor has AVX; bit moves either way.
pub fn transpose_rows(w: &[f32], inp: usize, out: usize, rows: Range<usize>, dst: &mut [f32]) {
    let (i0, n) = (rows.start, rows.len());
    assert!(rows.end <= inp && w.len() >= inp * out && dst.len() >= n * out);
    #[cfg(target_arch = "x86_64")]
    let (bi, bo) = if std::arch::is_x86_feature_detected!("avx") { (n - n % 8, out - out % 8) } else { (0, 0) };
    #[cfg(not(target_arch = "x86_64"))]
    let (bi, bo) = (0, 0);
    #[cfg(target_arch = "x86_64")]
    for r in (0..bi).step_by(8) {
        for o in (0..bo).step_by(8) {
            // SAFETY: AVX is present; rows o..o + 8 of w hold elements i0 + r..i0 + r + 8, and
            // dst's rows r..r + 8 hold columns o..o + 8 (the extents asserted above).
            unsafe { gemm::x86::transpose8(w.as_ptr().add(o * inp + i0 + r), inp, dst.as_mut_ptr().add(r * out + o), out) };
        }
    }
    // The edges the blocks leave: the last columns of the blocks' rows, then the last rows.
    for r in 0..n {
        let from = if r < bi { bo } else { 0 };
        for o in from..out {
            dst[r * out + o] = w[o * inp + i0 + r];
        }
    }
}

/// While alive, the calling thread flushes denormal floats to zero (x86-64 MXCSR FTZ and
/// DAZ). Adam's second moments of tiny gradients decay into the denormal range, where every
/// operation is about a hundred times slower: with the original code's N(0, 0.02^2)
/// initialisation, BC ran 4x slower after 3,000 iterations and kept slowing down. The
/// setting is per thread and restored on drop, so the simulator and PPO never see it.
pub struct FlushDenormals {
    #[cfg(target_arch = "x86_64")]
    saved: u32,
}

impl FlushDenormals {
    #[allow(deprecated)] // _mm_getcsr/_mm_setcsr: no stable replacement for setting MXCSR
    pub fn new() -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            // SAFETY: reads and writes this thread's SSE control register only.
            let saved = unsafe { std::arch::x86_64::_mm_getcsr() };
            unsafe { std::arch::x86_64::_mm_setcsr(saved | 0x8040) };
            FlushDenormals { saved }
        }
        #[cfg(not(target_arch = "x86_64"))]
        FlushDenormals {}
    }
}

impl Default for FlushDenormals {
    fn default() -> Self {
        Self::new()
    }
}

impl Drop for FlushDenormals {
    #[allow(deprecated)]
    fn drop(&mut self) {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: restores this thread's SSE control register.
        unsafe {
            std::arch::x86_64::_mm_setcsr(self.saved)
        };
    }
}
