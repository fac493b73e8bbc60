//! The x86-64 micro-kernels of [`super`] and the register transpose its packing (and
//! `kernels::bf16`'s) uses.
use std::arch::x86_64::*;

/// Writes the 8 x 8 block whose column `j` starts at `src + j * stride` (8 contiguous
/// elements) as 8 rows of 8 contiguous elements, `dst_stride` apart from `dst`: row `p`
/// holds element `p` of every column. Bit moves only, so it copies any 32-bit values
/// exactly (bf16 pairs too).
#[target_feature(enable = "avx")]
pub(in crate::kernels) unsafe fn transpose8(src: *const f32, stride: usize, dst: *mut f32, dst_stride: usize) {
    // SAFETY (all): the caller's extents.
    let r: [__m256; 8] = std::array::from_fn(|j| unsafe { _mm256_loadu_ps(src.add(j * stride)) });
    let t = [
        _mm256_unpacklo_ps(r[0], r[1]),
        _mm256_unpackhi_ps(r[0], r[1]),
        _mm256_unpacklo_ps(r[2], r[3]),
        _mm256_unpackhi_ps(r[2], r[3]),
        _mm256_unpacklo_ps(r[4], r[5]),
        _mm256_unpackhi_ps(r[4], r[5]),
        _mm256_unpacklo_ps(r[6], r[7]),
        _mm256_unpackhi_ps(r[6], r[7]),
    ];
    let u = [
        _mm256_shuffle_ps::<0x44>(t[0], t[2]),
        _mm256_shuffle_ps::<0xEE>(t[0], t[2]),
        _mm256_shuffle_ps::<0x44>(t[1], t[3]),
        _mm256_shuffle_ps::<0xEE>(t[1], t[3]),
        _mm256_shuffle_ps::<0x44>(t[4], t[6]),
        _mm256_shuffle_ps::<0xEE>(t[4], t[6]),
        _mm256_shuffle_ps::<0x44>(t[5], t[7]),
        _mm256_shuffle_ps::<0xEE>(t[5], t[7]),
    ];
    for p in 0..4 {
        unsafe {
            _mm256_storeu_ps(dst.add(dst_stride * p), _mm256_permute2f128_ps::<0x20>(u[p], u[p + 4]));
            _mm256_storeu_ps(dst.add(dst_stride * (p + 4)), _mm256_permute2f128_ps::<0x31>(u[p], u[p + 4]));
        }
    }
}

/// A micro-kernel of `MR` rows by two vectors of `W` lanes: per row two accumulators, per
/// term one broadcast of A's element and two fused multiply-adds.
macro_rules! micro_kernel {
    ($(#[$doc:meta])* $name:ident, $features:literal, $mr:literal, $w:literal,
     $zero:ident, $load:ident, $store:ident, $set1:ident, $fma:ident) => {
        $(#[$doc])*
        #[target_feature(enable = $features)]
        pub unsafe fn $name(kc: usize, a: *const f32, b: *const f32, ldb: usize, c: *mut f32, rs: usize, load: bool) {
            const MR: usize = $mr;
            let mut acc = [[$zero(); 2]; MR];
            if load {
                for (i, row) in acc.iter_mut().enumerate() {
                    row[0] = unsafe { $load(c.add(i * rs)) };
                    row[1] = unsafe { $load(c.add(i * rs + $w)) };
                }
            }
            for p in 0..kc {
                let b0 = unsafe { $load(b.add(p * ldb)) };
                let b1 = unsafe { $load(b.add(p * ldb + $w)) };
                for (i, row) in acc.iter_mut().enumerate() {
                    let av = $set1(unsafe { *a.add(p * MR + i) });
                    row[0] = $fma(av, b0, row[0]);
                    row[1] = $fma(av, b1, row[1]);
                }
            }
            for (i, row) in acc.iter().enumerate() {
                unsafe { $store(c.add(i * rs), row[0]) };
                unsafe { $store(c.add(i * rs + $w), row[1]) };
            }
        }
    };
}

micro_kernel!(
    /// 6 x 16: twelve accumulators of 8 lanes.
    avx2, "avx2,fma", 6, 8, _mm256_setzero_ps, _mm256_loadu_ps, _mm256_storeu_ps, _mm256_set1_ps, _mm256_fmadd_ps
);
micro_kernel!(
    /// 8 x 32: sixteen accumulators of 16 lanes.
    avx512, "avx512f,fma", 8, 16, _mm512_setzero_ps, _mm512_loadu_ps, _mm512_storeu_ps, _mm512_set1_ps, _mm512_fmadd_ps
);
