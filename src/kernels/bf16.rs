//! Matrix products with bf16 factors and f32 accumulation, whose bits depend on the shapes
//! alone, whatever the processor.
//!
//! The definition is AVX512-BF16's `VDPBF16PS`, which multiplies pairs of bf16 values and
//! adds both products to an f32 accumulator: every factor is rounded to bf16 (nearest, ties
//! to even; subnormals become zero), and every output is one chain over the summed dimension
//! taken in pairs, the odd term first (`p = 1, 0, 3, 2, ...`; an odd `k` is padded with a zero
//! term), each step `c = c + a * b` rounded once (the product of two bf16 values is exact in
//! f32), with subnormal results flushed to zero. Where the processor has AVX512-BF16 the
//! products run on it ([`Bf16Path::Native`], about twice the f32 rate); elsewhere the same
//! chains run through the f32 kernel ([`super::gemm`]) on the rounded, pair-swapped factors
//! with denormals flushed ([`Bf16Path::Emulated`]). `tests::native_matches_the_emulation`
//! checks that the two agree bit for bit wherever both run; measured on an AMD Zen 5
//! processor, the instruction computes exactly the odd-then-even chain the manuals give.
use super::gemm::{Factor, Kernel, Product, gemm_with};

/// How a product's factors are stored for the multiply: the reward and policy networks
/// train in either.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Precision {
    /// f32 factors (the default; the same bits as every earlier version).
    #[default]
    F32,
    /// bf16 factors with f32 accumulation (this module's definition).
    Bf16,
}

impl Precision {
    pub fn is_f32(&self) -> bool {
        *self == Precision::F32
    }
}

/// Where a bf16 product runs. Information only: both give the same bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Bf16Path {
    /// AVX512-BF16's `VDPBF16PS`.
    Native,
    /// The f32 kernel on rounded factors.
    Emulated(Kernel),
}

impl Bf16Path {
    pub fn native_supported() -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            std::arch::is_x86_feature_detected!("avx512bf16") && std::arch::is_x86_feature_detected!("avx512f")
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            false
        }
    }

    /// The path this process uses: native where the processor has it, unless
    /// [`super::gemm::KERNEL_ENV`] asks for a narrower f32 variant (tests and benchmarks
    /// compare the paths that way).
    pub fn active() -> Bf16Path {
        let kernel = Kernel::active();
        if kernel == Kernel::Avx512 && Self::native_supported() { Bf16Path::Native } else { Bf16Path::Emulated(kernel) }
    }

    pub fn name(self) -> String {
        match self {
            Bf16Path::Native => "avx512bf16".into(),
            Bf16Path::Emulated(k) => format!("{} (bf16 emulated)", k.name()),
        }
    }
}

/// f32 to bf16, nearest with ties to even; subnormals become zero of the same sign, NaN a
/// quiet NaN.
pub fn to_bf16(x: f32) -> u16 {
    bf16_bits(x) as u16
}

/// [`to_bf16`] in the low 16 bits, branch-free so that the packing loops vectorise.
#[inline(always)]
fn bf16_bits(x: f32) -> u32 {
    let bits = x.to_bits();
    let exp = bits & 0x7F80_0000;
    let rounded = bits.wrapping_add(0x7FFF + ((bits >> 16) & 1)) >> 16;
    let is_nan = exp == 0x7F80_0000 && (bits & 0x007F_FFFF) != 0;
    let special = if is_nan { (bits >> 16) | 0x40 } else { rounded };
    if exp == 0 { (bits >> 16) & 0x8000 } else { special }
}

pub fn from_bf16(h: u16) -> f32 {
    f32::from_bits((h as u32) << 16)
}

fn flush(x: f32) -> f32 {
    if x.is_subnormal() { 0.0f32.copysign(x) } else { x }
}

/// The product `p` into row-major `c` (rows `ldc` apart) in bf16 (the module's definition),
/// as [`super::gemm::gemm`] does in f32.
pub fn gemm_bf16(p: Product<'_>, c: &mut [f32], ldc: usize) {
    gemm_bf16_with(Bf16Path::active(), p, c, ldc)
}

/// [`gemm_bf16`] on a chosen path (tests and benchmarks compare them).
pub fn gemm_bf16_with(path: Bf16Path, p: Product<'_>, c: &mut [f32], ldc: usize) {
    let Product { m, n, k, a: Factor { data: a, ld: lda, transposed: ta }, b: Factor { data: b, ld: ldb, transposed: tb }, accumulate } = p;
    if m == 0 || n == 0 {
        return;
    }
    // op(A)(i, p) is a[i * ars + p * acs]; op(B)(p, j) is b[p * brs + j * bcs].
    let (ars, acs) = if ta { (1, lda) } else { (lda, 1) };
    let (brs, bcs) = if tb { (1, ldb) } else { (ldb, 1) };
    let need =
        |rows: usize, cols: usize, rs: usize, cs: usize| if rows == 0 || cols == 0 { 0 } else { (rows - 1) * rs + (cols - 1) * cs + 1 };
    assert!(a.len() >= need(m, k, ars, acs) && b.len() >= need(k, n, brs, bcs), "gemm: a buffer is too short");
    let at = |i: usize, p: usize| a[i * ars + p * acs];
    let bt = |p: usize, j: usize| b[p * brs + j * bcs];
    assert!(ldc >= n && c.len() >= (m - 1) * ldc + n, "gemm: C is too short");
    if accumulate {
        // The instruction reads its accumulator as if denormals were zero.
        for i in 0..m {
            c[i * ldc..i * ldc + n].iter_mut().for_each(|v| *v = flush(*v));
        }
    }
    match path {
        Bf16Path::Emulated(kernel) => {
            // The instruction flushes denormals whatever MXCSR says; the f32 kernel does so
            // under FTZ and DAZ.
            let _ftz = super::FlushDenormals::new();
            // The factors rounded, each pair's two terms swapped, an odd k padded: the f32
            // chain over this order is the instruction's.
            let kp = k.div_ceil(2) * 2;
            let swapped = |p: usize| p ^ 1;
            let mut ar = vec![0.0f32; m * kp];
            let mut br = vec![0.0f32; kp * n];
            for i in 0..m {
                for p in 0..k {
                    ar[i * kp + swapped(p)] = from_bf16(to_bf16(at(i, p)));
                }
            }
            for p in 0..k {
                for j in 0..n {
                    br[swapped(p) * n + j] = from_bf16(to_bf16(bt(p, j)));
                }
            }
            gemm_with(kernel, Product { m, n, k: kp, a: Factor::new(&ar, kp), b: Factor::new(&br, n), accumulate }, c, ldc);
        }
        Bf16Path::Native => {
            assert!(Bf16Path::native_supported(), "gemm_bf16_with: this processor has no AVX512-BF16");
            #[cfg(target_arch = "x86_64")]
            // SAFETY: the processor has the instructions (checked above); `native` reads the
            // packed copies and writes C inside the extents checked above.
            unsafe {
                native::product(m, n, k, (a, ars, acs), (b, brs, bcs), accumulate, c, ldc)
            };
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod native {
    use super::bf16_bits;
    use std::arch::x86_64::*;

    /// Rows and columns of a tile: sixteen accumulators of 16 lanes.
    const MR: usize = 8;
    const NR: usize = 32;
    /// Pairs of the summed dimension per block (each block continues the chains).
    const KCP: usize = 128;

    #[inline(always)]
    fn pair(even: f32, odd: f32) -> u32 {
        bf16_bits(even) | bf16_bits(odd) << 16
    }

    thread_local! {
        /// Packed pairs of A and B, reused across products on this thread.
        static PACKS: std::cell::RefCell<(Vec<u32>, Vec<u32>)> = const { std::cell::RefCell::new((Vec::new(), Vec::new())) };
    }

    /// Packs `width` (at most `w`) lines of `kc` pairs from the strided matrix `(x, along,
    /// across)` (element (line, p) at `line * across + p * along`), pairs `q0..q0 + kc` of
    /// the summed dimension (length `k`), into `kc` rows of `w` pairs, zero past the edges.
    #[allow(clippy::too_many_arguments)]
    #[target_feature(enable = "avx512f")]
    fn pack(dst: &mut [u32], x: &[f32], across: usize, along: usize, first: usize, width: usize, w: usize, q0: usize, kc: usize, k: usize) {
        dst[..kc * w].fill(0);
        if across == 1 {
            // Each term's lines are contiguous: two rows of the source make a row of pairs.
            for q in 0..kc {
                let (p0, p1) = (2 * (q0 + q), 2 * (q0 + q) + 1);
                let row = &mut dst[q * w..q * w + width];
                let even = &x[p0 * along + first..p0 * along + first + width];
                if p1 < k {
                    let odd = &x[p1 * along + first..p1 * along + first + width];
                    row.iter_mut().zip(even.iter().zip(odd)).for_each(|(d, (&e, &o))| *d = pair(e, o));
                } else {
                    row.iter_mut().zip(even).for_each(|(d, &e)| *d = pair(e, 0.0));
                }
            }
        } else if along == 1 {
            // Each line is contiguous along the summed dimension: adjacent terms make a pair.
            // Converted into a contiguous run first (which vectorises), then spread into the
            // panel's column.
            let full = kc.min((k / 2).saturating_sub(q0));
            if w == 8 && width == 8 {
                // Eight lines' runs, then 8 x 8 transposes in registers into the panel.
                let mut runs = [[0u32; KCP]; 8];
                for (l, run) in runs.iter_mut().enumerate() {
                    let line = &x[(first + l) * across + 2 * q0..];
                    for (r, t) in run[..full].iter_mut().zip(line[..2 * full].chunks_exact(2)) {
                        *r = pair(t[0], t[1]);
                    }
                    if full < kc {
                        run[full] = pair(line[2 * full], 0.0);
                    }
                }
                let blocks = kc / 8;
                for blk in 0..blocks {
                    // SAFETY: 8 runs of at least 8 x blk + 8 pairs; the panel holds kc rows of 8.
                    unsafe {
                        crate::kernels::gemm::x86::transpose8(
                            runs[0][8 * blk..].as_ptr().cast(),
                            KCP,
                            dst[64 * blk..].as_mut_ptr().cast(),
                            8,
                        )
                    };
                }
                for q in 8 * blocks..kc {
                    for (l, run) in runs.iter().enumerate() {
                        dst[q * w + l] = run[q];
                    }
                }
                return;
            }
            let mut run = [0u32; KCP];
            for l in 0..width {
                let line = &x[(first + l) * across + 2 * q0..];
                for (r, t) in run[..full].iter_mut().zip(line[..2 * full].chunks_exact(2)) {
                    *r = pair(t[0], t[1]);
                }
                if full < kc {
                    run[full] = pair(line[2 * full], 0.0);
                }
                for (q, &r) in run[..kc].iter().enumerate() {
                    dst[q * w + l] = r;
                }
            }
        } else {
            for q in 0..kc {
                let (p0, p1) = (2 * (q0 + q), 2 * (q0 + q) + 1);
                for l in 0..width {
                    let base = (first + l) * across;
                    let odd = if p1 < k { x[base + p1 * along] } else { 0.0 };
                    dst[q * w + l] = pair(x[base + p0 * along], odd);
                }
            }
        }
    }

    /// `C (+)= op(A) op(B)`, `a` and `b` as (buffer, row stride, column stride).
    #[allow(clippy::too_many_arguments)]
    pub unsafe fn product(
        m: usize,
        n: usize,
        k: usize,
        a: (&[f32], usize, usize),
        b: (&[f32], usize, usize),
        accumulate: bool,
        c: &mut [f32],
        ldc: usize,
    ) {
        let pairs = k.div_ceil(2);
        let (mp, np) = (m.div_ceil(MR), n.div_ceil(NR));
        PACKS.with(|packs| {
            let (apack, bpack) = &mut *packs.borrow_mut();
            for q0 in (0..pairs.max(1)).step_by(KCP) {
                let kc = KCP.min(pairs - q0);
                let load = accumulate || q0 > 0;
                apack.resize(mp * MR * kc, 0);
                bpack.resize(np * NR * kc, 0);
                // B's columns are the lines (across: its column stride), p runs down them.
                for panel in 0..np {
                    let dst = &mut bpack[panel * kc * NR..(panel + 1) * kc * NR];
                    // SAFETY: the processor has AVX-512 (the caller checked AVX512-BF16).
                    unsafe { pack(dst, b.0, b.2, b.1, panel * NR, NR.min(n - panel * NR), NR, q0, kc, k) };
                }
                for panel in 0..mp {
                    let dst = &mut apack[panel * kc * MR..(panel + 1) * kc * MR];
                    unsafe { pack(dst, a.0, a.1, a.2, panel * MR, MR.min(m - panel * MR), MR, q0, kc, k) };
                }
                for ip in 0..mp {
                    for jp in 0..np {
                        let (rows, cols) = (MR.min(m - ip * MR), NR.min(n - jp * NR));
                        let origin = ip * MR * ldc + jp * NR;
                        let ap = apack[ip * kc * MR..].as_ptr();
                        let bp = bpack[jp * kc * NR..].as_ptr();
                        if rows == MR && cols == NR {
                            // SAFETY: the panels hold kc x MR and kc x NR pairs; the tile
                            // lies inside C (rows of `ldc`).
                            unsafe { micro(kc, ap, bp, c[origin..].as_mut_ptr(), ldc, load) };
                            continue;
                        }
                        let mut local = [0.0f32; MR * NR];
                        if load {
                            for i in 0..rows {
                                local[i * NR..i * NR + cols].copy_from_slice(&c[origin + i * ldc..origin + i * ldc + cols]);
                            }
                        }
                        // SAFETY: as above; `local` is MR x NR.
                        unsafe { micro(kc, ap, bp, local.as_mut_ptr(), NR, load) };
                        for i in 0..rows {
                            c[origin + i * ldc..origin + i * ldc + cols].copy_from_slice(&local[i * NR..i * NR + cols]);
                        }
                    }
                }
            }
        })
    }

    /// One MR x NR tile over `kc` pairs: per pair two loads of B, per row a broadcast of A's
    /// pair and two `VDPBF16PS`.
    #[target_feature(enable = "avx512f,avx512bf16")]
    unsafe fn micro(kc: usize, a: *const u32, b: *const u32, c: *mut f32, rs: usize, load: bool) {
        let mut acc = [[_mm512_setzero_ps(); 2]; MR];
        if load {
            for (i, row) in acc.iter_mut().enumerate() {
                row[0] = unsafe { _mm512_loadu_ps(c.add(i * rs)) };
                row[1] = unsafe { _mm512_loadu_ps(c.add(i * rs + 16)) };
            }
        }
        for q in 0..kc {
            // SAFETY (all): inside the panels, whose rows are NR and MR pairs.
            let b0: __m512bh = unsafe { std::mem::transmute(_mm512_loadu_si512(b.add(q * NR).cast())) };
            let b1: __m512bh = unsafe { std::mem::transmute(_mm512_loadu_si512(b.add(q * NR + 16).cast())) };
            for (i, row) in acc.iter_mut().enumerate() {
                let av: __m512bh = unsafe { std::mem::transmute(_mm512_set1_epi32(*a.add(q * MR + i) as i32)) };
                row[0] = _mm512_dpbf16_ps(row[0], av, b0);
                row[1] = _mm512_dpbf16_ps(row[1], av, b1);
            }
        }
        for (i, row) in acc.iter().enumerate() {
            unsafe { _mm512_storeu_ps(c.add(i * rs), row[0]) };
            unsafe { _mm512_storeu_ps(c.add(i * rs + 16), row[1]) };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernels::gemm::test_values as values;

    /// The definition, element by element.
    fn reference(p: Product<'_>, c: &mut [f32], ldc: usize) {
        let Product { m, n, k, a: Factor { data: a, ld: lda, transposed: ta }, b: Factor { data: b, ld: ldb, transposed: tb }, accumulate } =
            p;
        let r = |x: f32| from_bf16(to_bf16(x));
        for i in 0..m {
            for j in 0..n {
                let mut acc = if accumulate { flush(c[i * ldc + j]) } else { 0.0 };
                for q in 0..k.div_ceil(2) {
                    for p in [2 * q + 1, 2 * q] {
                        let (x, y) = if p < k {
                            (r(if ta { a[p * lda + i] } else { a[i * lda + p] }), r(if tb { b[j * ldb + p] } else { b[p * ldb + j] }))
                        } else {
                            (0.0, 0.0)
                        };
                        acc = flush(x.mul_add(y, acc));
                    }
                }
                c[i * ldc + j] = acc;
            }
        }
    }

    fn paths() -> Vec<Bf16Path> {
        let mut paths: Vec<Bf16Path> = Kernel::ALL.into_iter().filter(|k| k.supported()).map(Bf16Path::Emulated).collect();
        for k in Kernel::ALL.into_iter().filter(|k| !k.supported()) {
            super::super::narrowed("kernels::bf16::tests (every path)", k.name());
        }
        if Bf16Path::native_supported() {
            paths.push(Bf16Path::Native);
        } else {
            super::super::narrowed("kernels::bf16::tests (every path)", "AVX512-BF16");
        }
        paths
    }

    /// Every path this processor has gives the definition's bits (and so each other's), in
    /// every transpose, at odd k, at tile edges, across blocks of the summed dimension, for
    /// C written over and accumulated, with subnormal and tiny values among the inputs.
    #[test]
    fn native_matches_the_emulation() {
        let shapes = [(1, 1, 1), (5, 3, 4), (7, 17, 33), (64, 256, 17), (9, 40, 600), (33, 65, 257), (4, 4, 0)];
        for &(m, n, k) in &shapes {
            for (ta, tb) in [(false, false), (true, false), (false, true), (true, true)] {
                let (lda, ldb, ldc) = (if ta { m + 1 } else { k + 2 }, if tb { k + 3 } else { n + 1 }, n + 2);
                let mut a = values(if ta { k * lda } else { m * lda }, 0.37);
                let b = values(if tb { n * ldb } else { k * ldb }, 0.91);
                let mut c0 = values(m * ldc, 0.13);
                // Subnormal factors and accumulators, and products that cancel to tiny sums.
                a.iter_mut().step_by(11).for_each(|v| *v *= 1e-39);
                c0.iter_mut().step_by(7).for_each(|v| *v *= 1e-40);
                for accumulate in [false, true] {
                    let p = Product {
                        m,
                        n,
                        k,
                        a: Factor { data: &a, ld: lda, transposed: ta },
                        b: Factor { data: &b, ld: ldb, transposed: tb },
                        accumulate,
                    };
                    let mut want = c0.clone();
                    reference(p, &mut want, ldc);
                    for path in paths() {
                        let mut got = c0.clone();
                        gemm_bf16_with(path, p, &mut got, ldc);
                        let differ = (0..m * ldc).filter(|&e| e % ldc < n && got[e].to_bits() != want[e].to_bits()).count();
                        assert_eq!(
                            differ,
                            0,
                            "{} {m}x{n}x{k} ta {ta} tb {tb} accumulate {accumulate}: {differ} elements differ",
                            path.name()
                        );
                    }
                }
            }
        }
    }

    /// Rounding: nearest, ties to even, subnormals to zero, NaN stays NaN.
    #[test]
    fn rounds_to_nearest_even() {
        assert_eq!(to_bf16(1.0), 0x3F80);
        // 1 + 2^-8 is half-way between 1 and 1 + 2^-7: ties to the even 1.
        assert_eq!(to_bf16(1.0 + 2f32.powi(-8)), 0x3F80);
        // 1 + 3 x 2^-8 is half-way between 1 + 2^-7 (odd) and 1 + 2^-6: up.
        assert_eq!(to_bf16(1.0 + 3.0 * 2f32.powi(-8)), 0x3F82);
        assert_eq!(to_bf16(-1e-40), 0x8000);
        assert!(from_bf16(to_bf16(f32::NAN)).is_nan());
        assert_eq!(from_bf16(to_bf16(f32::MAX)), f32::INFINITY);
        assert!((from_bf16(to_bf16(0.1)) - 0.1).abs() < 0.1 * 2f32.powi(-8));
    }
}
