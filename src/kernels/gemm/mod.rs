//! Single-precision matrix products whose bits depend on the shapes alone, whatever the
//! processor.
//!
//! Every output is one chain of fused multiply-adds over the summed dimension in index
//! order, `c = fma(a[i][p], b[p][j], c)` for `p = 0, 1, ..., k-1`, started from `C` (accumulating)
//! or from zero. The kernels vectorise across outputs only, never across the summed
//! dimension, and block that dimension into consecutive runs that continue the same chain,
//! so neither the vector width, the tile shape, the block sizes nor the orientation (a
//! product may be computed transposed, which swaps the two factors of each multiply, and
//! `fma` is exact in its product) changes a bit. The [`Kernel`] variants (scalar `mul_add`,
//! AVX2 and AVX-512) therefore give the same bytes on any x86-64 processor with FMA:
//! `tests::variants_agree_bit_for_bit` checks it, and the smoke pipeline's digests are
//! compared across variants in `tests/pipeline.rs`.
//!
//! BLAS libraries (MKL inside libtorch) choose their summation order per processor, which
//! made stored bytes depend on the machine; that is why idrex has its own.
use std::sync::OnceLock;

/// The environment variable that forces a [`Kernel`] variant (`scalar`, `avx2`, `avx512`;
/// `auto` or unset: the widest the processor has).
pub const KERNEL_ENV: &str = "IDREX_KERNEL";

/// The instruction sets the products (and the learners' elementwise passes) can run on.
/// Information only: every variant computes the same bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kernel {
    Scalar,
    Avx2,
    Avx512,
}

impl Kernel {
    pub const ALL: [Kernel; 3] = [Kernel::Scalar, Kernel::Avx2, Kernel::Avx512];

    pub fn name(self) -> &'static str {
        match self {
            Kernel::Scalar => "scalar",
            Kernel::Avx2 => "avx2",
            Kernel::Avx512 => "avx512",
        }
    }

    /// Whether this processor can run the variant (each needs FMA: a multiply-add rounded
    /// once is what makes the variants agree).
    pub fn supported(self) -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            let fma = std::arch::is_x86_feature_detected!("fma");
            match self {
                Kernel::Scalar => fma,
                Kernel::Avx2 => fma && std::arch::is_x86_feature_detected!("avx2"),
                Kernel::Avx512 => fma && std::arch::is_x86_feature_detected!("avx512f"),
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            self == Kernel::Scalar
        }
    }

    /// The widest variant this processor has.
    pub fn best() -> Option<Kernel> {
        Kernel::ALL.into_iter().rev().find(|k| k.supported())
    }

    /// The variant [`KERNEL_ENV`] asks for, checked against this processor.
    pub fn from_env() -> Result<Kernel, String> {
        let asked = std::env::var(KERNEL_ENV).unwrap_or_default();
        let kernel = match asked.as_str() {
            "" | "auto" => {
                return Kernel::best().ok_or_else(|| "this processor has no FMA instructions, which idrex's matrix products need".into());
            }
            name => Kernel::ALL
                .into_iter()
                .find(|k| k.name() == name)
                .ok_or_else(|| format!("{KERNEL_ENV}={name} is not a kernel variant; use auto, scalar, avx2 or avx512"))?,
        };
        if !kernel.supported() {
            return Err(format!("{KERNEL_ENV}={} asks for instructions this processor lacks; use auto", kernel.name()));
        }
        Ok(kernel)
    }

    /// The variant in use, chosen once per process from [`KERNEL_ENV`] (the binary checks it
    /// at start and refuses a bad value; here a bad value falls back to the best variant).
    pub fn active() -> Kernel {
        static ACTIVE: OnceLock<Kernel> = OnceLock::new();
        *ACTIVE.get_or_init(|| Kernel::from_env().unwrap_or_else(|_| Kernel::best().unwrap_or(Kernel::Scalar)))
    }
}

/// A strided matrix: element (i, j) is at `i * rs + j * cs`.
#[derive(Clone, Copy)]
struct View {
    ptr: *const f32,
    rs: usize,
    cs: usize,
}

impl View {
    /// The view from element (i, j) on.
    unsafe fn offset(self, i: usize, j: usize) -> View {
        // SAFETY: the caller stays inside the extents checked by `gemm`.
        View { ptr: unsafe { self.ptr.add(i * self.rs + j * self.cs) }, ..self }
    }
    fn t(self) -> View {
        View { ptr: self.ptr, rs: self.cs, cs: self.rs }
    }
}

#[derive(Clone, Copy)]
struct ViewMut {
    ptr: *mut f32,
    rs: usize,
    cs: usize,
}

impl ViewMut {
    fn t(self) -> ViewMut {
        ViewMut { ptr: self.ptr, rs: self.cs, cs: self.rs }
    }
}

/// One factor of a product: row-major `data` with `ld` elements between rows (BLAS's
/// leading dimension), read transposed where `transposed`.
#[derive(Debug, Clone, Copy)]
pub struct Factor<'a> {
    pub data: &'a [f32],
    pub ld: usize,
    pub transposed: bool,
}

impl<'a> Factor<'a> {
    /// `data` as stored, rows `ld` apart.
    pub fn new(data: &'a [f32], ld: usize) -> Self {
        Factor { data, ld, transposed: false }
    }

    /// `data` transposed, its stored rows `ld` apart.
    pub fn t(data: &'a [f32], ld: usize) -> Self {
        Factor { data, ld, transposed: true }
    }
}

/// A matrix product `C (m x n) = op(A) op(B)`, op(A) `m x k` and op(B) `k x n`: written over
/// C, or added to it where `accumulate` (BLAS's beta, which here could only be 0 or 1).
#[derive(Debug, Clone, Copy)]
pub struct Product<'a> {
    pub m: usize,
    pub n: usize,
    pub k: usize,
    pub a: Factor<'a>,
    pub b: Factor<'a>,
    pub accumulate: bool,
}

/// The product `p` into row-major `c`, rows `ldc` apart; see the module documentation for
/// the order of the sums.
pub fn gemm(p: Product<'_>, c: &mut [f32], ldc: usize) {
    gemm_with(Kernel::active(), p, c, ldc)
}

/// The summed dimension is computed in consecutive blocks of this many terms, each
/// continuing the chains of the one before (a constant, so the order never depends on the
/// machine's caches).
const KC: usize = 256;
/// Rows of A packed at once (a multiple of every variant's tile height).
const MC: usize = 96;
/// Columns of B packed at once.
const NC: usize = 512;

/// The tile a variant's micro-kernel computes: `MR` rows by `NR` columns.
fn tile(kernel: Kernel) -> (usize, usize) {
    match kernel {
        Kernel::Scalar => (4, 4),
        Kernel::Avx2 => (6, 16),
        Kernel::Avx512 => (8, 32),
    }
}

#[allow(clippy::too_many_arguments)]
unsafe fn product(kernel: Kernel, m: usize, n: usize, k: usize, a: View, b: View, c: ViewMut, accumulate: bool) {
    let (mr, nr) = tile(kernel);
    // The padded work of each orientation; C' = B' A' computes every element with the same
    // chain, its two factors swapped.
    let padded = |m: usize, n: usize| m.div_ceil(mr) * mr * n.div_ceil(nr) * nr;
    if padded(n, m) < padded(m, n) {
        // SAFETY: the same elements, addressed transposed.
        return unsafe { product(kernel, n, m, k, b.t(), a.t(), c.t(), accumulate) };
    }
    // B is read in place where its rows are contiguous (only a partial last panel is
    // packed, so that no read passes the row's end); otherwise it is packed.
    let direct = b.cs == 1;
    PACKS.with(|p| {
        let (apack, bpack) = &mut *p.borrow_mut();
        for jc in (0..n).step_by(NC) {
            let nc = NC.min(n - jc);
            let edge = nc - nc % nr;
            for pc in (0..k.max(1)).step_by(KC) {
                let kc = KC.min(k - pc);
                // A fresh product starts from zero; every later block (and accumulation) continues from C.
                let load = accumulate || pc > 0;
                // SAFETY: the blocks lie inside A, B and C (the extents `gemm` checked).
                unsafe {
                    if !direct {
                        pack(bpack, kc, nc, nr, b.offset(pc, jc));
                    } else if edge < nc {
                        pack(bpack, kc, nc - edge, nr, b.offset(pc, jc + edge));
                    }
                }
                for ic in (0..m).step_by(MC) {
                    let mc = MC.min(m - ic);
                    unsafe { pack(apack, kc, mc, mr, a.offset(ic, pc).t()) };
                    for jr in (0..nc).step_by(nr) {
                        let (bp, ldb) = match (direct, jr < edge) {
                            (false, _) => (bpack[jr * kc..].as_ptr(), nr),
                            (true, true) => (unsafe { b.offset(pc, jc + jr) }.ptr, b.rs),
                            (true, false) => (bpack.as_ptr(), nr),
                        };
                        for ir in (0..mc).step_by(mr) {
                            let ap = apack[ir * kc..].as_ptr();
                            let cp = unsafe { c.ptr.add((ic + ir) * c.rs + (jc + jr) * c.cs) };
                            let cv = ViewMut { ptr: cp, rs: c.rs, cs: c.cs };
                            let (rows, cols) = (mr.min(mc - ir), nr.min(nc - jr));
                            unsafe { micro(kernel, kc, ap, bp, ldb, cv, rows, cols, load) };
                        }
                    }
                }
            }
        }
    });
}

thread_local! {
    /// Packed blocks of A and B, reused across products on this thread.
    static PACKS: std::cell::RefCell<(Vec<f32>, Vec<f32>)> = const { std::cell::RefCell::new((Vec::new(), Vec::new())) };
}

/// Packs the `kc x cols` block of `src` into panels of `w` columns, each `kc x w` row-major
/// and zero-padded at the edge: element (p, j) of panel q is `src(p, q * w + j)`.
unsafe fn pack(dst: &mut Vec<f32>, kc: usize, cols: usize, w: usize, src: View) {
    let panels = cols.div_ceil(w);
    dst.resize(panels * w * kc, 0.0);
    for q in 0..panels {
        let panel = &mut dst[q * w * kc..(q + 1) * w * kc];
        let width = w.min(cols - q * w);
        // SAFETY (all three): the caller's block lies inside the matrix.
        let at = |p: usize, j: usize| unsafe { src.ptr.add(p * src.rs + (q * w + j) * src.cs) };
        if src.cs == 1 {
            // Rows of the panel are contiguous in the source.
            for p in 0..kc {
                let row = unsafe { std::slice::from_raw_parts(at(p, 0), width) };
                panel[p * w..p * w + width].copy_from_slice(row);
            }
        } else if src.rs == 1 {
            // Columns are: transpose 8 x 8 blocks in registers where the panel is 8 wide (the
            // AVX-512 variant's A panels, whose scalar scatter was a fifth of T-REX's product
            // time), then read the rest of each column in order.
            #[cfg(target_arch = "x86_64")]
            let done = if w == 8 && width == 8 && std::arch::is_x86_feature_detected!("avx") {
                let blocks = kc / 8;
                for blk in 0..blocks {
                    // SAFETY: 8 columns of 8 elements from row 8 x blk lie inside the block;
                    // the panel holds rows 8 x blk .. 8 x blk + 8 of 8 elements.
                    unsafe { x86::transpose8(at(8 * blk, 0), src.cs, panel[64 * blk..].as_mut_ptr(), 8) };
                }
                blocks * 8
            } else {
                0
            };
            #[cfg(not(target_arch = "x86_64"))]
            let done = 0;
            for j in 0..width {
                let col = unsafe { std::slice::from_raw_parts(at(0, j), kc) };
                for (p, &v) in col.iter().enumerate().skip(done) {
                    panel[p * w + j] = v;
                }
            }
        } else {
            for p in 0..kc {
                for j in 0..width {
                    panel[p * w + j] = unsafe { *at(p, j) };
                }
            }
        }
        if width < w {
            for p in 0..kc {
                panel[p * w + width..(p + 1) * w].fill(0.0);
            }
        }
    }
}

/// One tile: `C[..rows][..cols]` (+)= the product over `kc` terms of a packed panel of A
/// and a panel of B whose rows are `ldb` apart.
#[allow(clippy::too_many_arguments)]
unsafe fn micro(kernel: Kernel, kc: usize, a: *const f32, b: *const f32, ldb: usize, c: ViewMut, rows: usize, cols: usize, load: bool) {
    let (mr, nr) = tile(kernel);
    let full = rows == mr && cols == nr && c.cs == 1;
    // Edges and transposed outputs go through a contiguous tile on the stack.
    let mut local = [0.0f32; 8 * 32];
    let (ptr, rs) = if full {
        (c.ptr, c.rs)
    } else {
        if load {
            for i in 0..rows {
                for j in 0..cols {
                    local[i * nr + j] = unsafe { *c.ptr.add(i * c.rs + j * c.cs) };
                }
            }
        }
        (local.as_mut_ptr(), nr)
    };
    // SAFETY: each variant runs only where `Kernel::supported` holds (`Kernel::active`), and
    // writes the mr x nr tile at `ptr` with row stride `rs`.
    unsafe {
        match kernel {
            Kernel::Scalar => scalar(kc, a, b, ldb, ptr, rs, load),
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2 => x86::avx2(kc, a, b, ldb, ptr, rs, load),
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx512 => x86::avx512(kc, a, b, ldb, ptr, rs, load),
            #[cfg(not(target_arch = "x86_64"))]
            _ => unreachable!("only the scalar variant exists off x86-64"),
        }
    }
    if !full {
        for i in 0..rows {
            for j in 0..cols {
                unsafe { *c.ptr.add(i * c.rs + j * c.cs) = local[i * nr + j] };
            }
        }
    }
}

/// The reference: `f32::mul_add`, one element at a time (compiled with FMA, so that it is
/// the instruction and not libm's software fma, which would ignore the flushing of denormals).
#[cfg_attr(target_arch = "x86_64", target_feature(enable = "fma"))]
unsafe fn scalar(kc: usize, a: *const f32, b: *const f32, ldb: usize, c: *mut f32, rs: usize, load: bool) {
    const MR: usize = 4;
    const NR: usize = 4;
    let mut acc = [[0.0f32; NR]; MR];
    if load {
        for (i, row) in acc.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = unsafe { *c.add(i * rs + j) };
            }
        }
    }
    for p in 0..kc {
        for (i, row) in acc.iter_mut().enumerate() {
            let av = unsafe { *a.add(p * MR + i) };
            for (j, v) in row.iter_mut().enumerate() {
                *v = av.mul_add(unsafe { *b.add(p * ldb + j) }, *v);
            }
        }
    }
    for (i, row) in acc.iter().enumerate() {
        for (j, v) in row.iter().enumerate() {
            unsafe { *c.add(i * rs + j) = *v };
        }
    }
}

#[cfg(target_arch = "x86_64")]
pub(super) mod x86;

/// [`gemm`] on a chosen variant (tests and benchmarks compare them).
pub fn gemm_with(kernel: Kernel, p: Product<'_>, c: &mut [f32], ldc: usize) {
    let Product { m, n, k, a: Factor { data: a, ld: lda, transposed: ta }, b: Factor { data: b, ld: ldb, transposed: tb }, accumulate } = p;
    assert!(kernel.supported(), "gemm_with: this processor cannot run {}", kernel.name());
    if m == 0 || n == 0 {
        return;
    }
    // op(A) is m x k: A is stored m x k (lda >= k) or, transposed, k x m (lda >= m).
    let (ar, ac) = if ta { (k, m) } else { (m, k) };
    let (br, bc) = if tb { (n, k) } else { (k, n) };
    let need = |rows: usize, cols: usize, ld: usize| if rows == 0 { 0 } else { (rows - 1) * ld + cols };
    assert!(lda >= ac && ldb >= bc && ldc >= n, "gemm: a leading dimension is shorter than its row");
    assert!(a.len() >= need(ar, ac, lda) && b.len() >= need(br, bc, ldb) && c.len() >= need(m, n, ldc), "gemm: a buffer is too short");
    let av = if ta { View { ptr: a.as_ptr(), rs: 1, cs: lda } } else { View { ptr: a.as_ptr(), rs: lda, cs: 1 } };
    let bv = if tb { View { ptr: b.as_ptr(), rs: 1, cs: ldb } } else { View { ptr: b.as_ptr(), rs: ldb, cs: 1 } };
    let cv = ViewMut { ptr: c.as_mut_ptr(), rs: ldc, cs: 1 };
    // SAFETY: every element the product touches lies inside the extents checked above.
    unsafe { product(kernel, m, n, k, av, bv, cv, accumulate) }
}

/// Test operands of varied sign and magnitude (the products' tests share them).
#[cfg(test)]
pub(crate) fn test_values(n: usize, k: f32) -> Vec<f32> {
    (0..n).map(|i| ((i as f32 * k).sin() * 3.0).powi(3)).collect()
}

#[cfg(test)]
mod tests {
    use super::test_values as values;
    use super::*;

    /// The specification, element by element: one `mul_add` chain over the summed dimension.
    fn reference(p: Product<'_>, c: &mut [f32], ldc: usize) {
        let Product { m, n, k, a: Factor { data: a, ld: lda, transposed: ta }, b: Factor { data: b, ld: ldb, transposed: tb }, accumulate } =
            p;
        for i in 0..m {
            for j in 0..n {
                let mut acc = if accumulate { c[i * ldc + j] } else { 0.0 };
                for p in 0..k {
                    let x = if ta { a[p * lda + i] } else { a[i * lda + p] };
                    let y = if tb { b[j * ldb + p] } else { b[p * ldb + j] };
                    acc = x.mul_add(y, acc);
                }
                c[i * ldc + j] = acc;
            }
        }
    }

    /// Every variant this processor has gives the reference's bits, in every transpose, at
    /// edges, across blocks of the summed dimension and of rows and columns, written over C and accumulated.
    #[test]
    fn variants_agree_bit_for_bit() {
        let shapes = [
            (1, 1, 1),
            (5, 3, 4),
            (7, 17, 33),
            (64, 256, 17),
            (17, 256, 64),
            (130, 1, 256),
            (1, 130, 256),
            (9, 40, 600),
            (200, 530, 3),
            (4, 4, 0),
        ];
        let kernels: Vec<Kernel> = Kernel::ALL.into_iter().filter(|k| k.supported()).collect();
        assert!(!kernels.is_empty());
        for k in Kernel::ALL.into_iter().filter(|k| !k.supported()) {
            super::super::narrowed("kernels::gemm::tests::variants_agree_bit_for_bit", k.name());
        }
        for &(m, n, k) in &shapes {
            for (ta, tb) in [(false, false), (true, false), (false, true), (true, true)] {
                let (lda, ldb, ldc) = (if ta { m + 1 } else { k + 2 }, if tb { k + 3 } else { n + 1 }, n + 2);
                let a = values(if ta { k * lda } else { m * lda }, 0.37);
                let b = values(if tb { n * ldb } else { k * ldb }, 0.91);
                let c0 = values(m * ldc, 0.13);
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
                    for &kernel in &kernels {
                        let mut got = c0.clone();
                        gemm_with(kernel, p, &mut got, ldc);
                        let differ = got.iter().zip(&want).filter(|(g, w)| g.to_bits() != w.to_bits()).count();
                        assert_eq!(
                            differ,
                            0,
                            "{} {m}x{n}x{k} ta {ta} tb {tb} accumulate {accumulate}: {differ} elements differ",
                            kernel.name()
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn names_and_refuses_variants() {
        assert!(Kernel::best().is_some_and(Kernel::supported));
        assert!(Kernel::ALL.iter().all(|k| Kernel::ALL.iter().filter(|o| o.name() == k.name()).count() == 1));
        assert!(Kernel::active().supported());
    }
}
