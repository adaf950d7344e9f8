//! Stack high-water mark: cortex-m-rt (`paint-stack`) fills the stack with
//! [`cortex_m_rt::STACK_PAINT_VALUE`] before `main`; the deepest word no longer holding
//! it marks the most stack ever used.

/// Bytes of stack used so far at most (from the top of RAM down to the deepest write).
pub fn peak_bytes() -> u32 {
    unsafe extern "C" {
        static _stack_start: u32;
        static _stack_end: u32;
    }
    let top = &raw const _stack_start as usize;
    let mut p = &raw const _stack_end as usize;
    while p < top {
        // SAFETY: [_stack_end, _stack_start) is RAM reserved for the stack by the linker
        // script; reading a word of it has no side effect. Volatile: the compiler must
        // not assume anything about memory it did not write.
        let word = unsafe { core::ptr::read_volatile(p as *const u32) };
        if word != cortex_m_rt::STACK_PAINT_VALUE {
            break;
        }
        p += 4;
    }
    (top - p) as u32
}
