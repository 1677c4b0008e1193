//! A checked wrapper around the `gemm` crate: row-major matrix views with strides, and one
//! product into a row-major output.

use gemm::Parallelism;

/// A row-major matrix view, read with the given strides (a transpose swaps them).
#[derive(Clone, Copy)]
pub struct Matrix<'a> {
    pub data: &'a [f32],
    rows: usize,
    columns: usize,
    row_stride: usize,
    column_stride: usize,
}

impl<'a> Matrix<'a> {
    /// `data` as `rows x columns`, row-major.
    pub fn new(data: &'a [f32], rows: usize, columns: usize) -> Self {
        assert_eq!(data.len(), rows * columns, "matrix length");
        Self {
            data,
            rows,
            columns,
            row_stride: columns,
            column_stride: 1,
        }
    }

    pub fn transposed(self) -> Self {
        Self {
            rows: self.columns,
            columns: self.rows,
            row_stride: self.column_stride,
            column_stride: self.row_stride,
            ..self
        }
    }
}

/// `out` (`lhs.rows x rhs.columns`, row-major) = `lhs x rhs`, plus `out`'s old value when
/// `accumulate`.
pub fn matmul(
    out: &mut [f32],
    lhs: Matrix,
    rhs: Matrix,
    accumulate: bool,
    parallelism: Parallelism,
) {
    let (m, n, k) = (lhs.rows, rhs.columns, lhs.columns);
    assert_eq!(rhs.rows, k, "inner dimensions");
    assert_eq!(out.len(), m * n, "output length");
    // SAFETY: `Matrix::new` checked that each view's rows and columns, read with its strides,
    // cover exactly its slice, and `out` holds m x n with row stride n; `out` is a unique
    // borrow, so it does not alias the inputs.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            out.as_mut_ptr(),
            1,
            n as isize,
            accumulate,
            lhs.data.as_ptr(),
            lhs.column_stride as isize,
            lhs.row_stride as isize,
            rhs.data.as_ptr(),
            rhs.column_stride as isize,
            rhs.row_stride as isize,
            if accumulate { 1.0 } else { 0.0 },
            1.0,
            false,
            false,
            false,
            parallelism,
        );
    }
}

/// `sum += part`, element by element (a thread's share of a gradient into the total).
pub fn add_into(sum: &mut [f32], part: &[f32]) {
    assert_eq!(sum.len(), part.len(), "partial sum length");
    sum.iter_mut().zip(part).for_each(|(s, p)| *s += p);
}
