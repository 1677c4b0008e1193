//! The process allocator: mimalloc, told to keep freed memory mapped.
//!
//! Every forward pass and training step allocates and frees the same large tensors. glibc
//! unmaps each freed block over 32 MB and page-faults it back in on the next pass (a batch-8
//! forward pass ran 2x slower). mimalloc reuses freed blocks, but by default still hands idle
//! pages back to the OS after a delay: `ssr-agent bench --config cpu-default --train
//! --iterations 5` (eight batch-8 training steps) took 41,500 page faults, and the kernel zeroing fresh pages was 28 % of a step. With purging
//! off it takes 830, all while the first step grows the heap; the resident size stays at the
//! process's high-water mark instead (a few hundred MiB when serving).

#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// `mi_option_purge_delay`: its index in `mi_option_t`, the same in mimalloc 2 and 3 (the
/// bindings name the options around it but not this one; `MIMALLOC_PURGE_DELAY` sets it).
const PURGE_DELAY: libmimalloc_sys::mi_option_t = 15;

/// Never give freed pages back to the OS. Call first thing in `main`.
pub fn keep_freed_memory() {
    // SAFETY: sets one integer option; called before any other thread exists.
    unsafe { libmimalloc_sys::mi_option_set(PURGE_DELAY, -1) };
}
