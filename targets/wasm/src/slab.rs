//! The pools of the model [`crate::mochi_load`] loads: runs of zero-initialised statics, which
//! cost the module nothing (they are not in its data section). A `heapless::Vec` static would
//! be: the storage around it is not all zero bytes, so the whole static, megabytes of weights
//! room, would be written into the module.

use core::ptr::addr_of_mut;

use mochi_runtime::artifact::Pool;

/// Weights and biases room.
pub const PARAMS_CAPACITY: usize = 2 << 20;
/// Other reals room.
pub const FLOATS_CAPACITY: usize = 1 << 17;
/// Indices room.
pub const INDICES_CAPACITY: usize = 1 << 18;

static mut PARAMS: [f32; PARAMS_CAPACITY] = [0.0; PARAMS_CAPACITY];
static mut FLOATS: [f32; FLOATS_CAPACITY] = [0.0; FLOATS_CAPACITY];
static mut INDICES: [u32; INDICES_CAPACITY] = [0; INDICES_CAPACITY];
/// Whether each static above has been handed out (each may be, once).
static mut TAKEN: [bool; 3] = [false; 3];

/// A pool over the static `POOL` (0 params, 1 floats, 2 indices).
pub struct Slab<T: 'static, const POOL: usize> {
    items: &'static mut [T],
    len: usize,
}

/// The static `pool` the first time it is asked for, an empty slice after that (so that no
/// two slabs share one: a second one has no room, and loading into it fails cleanly).
fn take<T>(pool: usize, items: *mut [T]) -> &'static mut [T] {
    // SAFETY: wasm32-unknown-unknown runs one thread; TAKEN hands each static out at most
    // once, so the returned reference is the only one to it.
    unsafe {
        let taken = &mut *addr_of_mut!(TAKEN);
        if taken[pool] {
            return &mut [];
        }
        taken[pool] = true;
        &mut *items
    }
}

impl Default for Slab<f32, 0> {
    fn default() -> Self {
        Slab {
            items: take(0, addr_of_mut!(PARAMS) as *mut [f32]),
            len: 0,
        }
    }
}

impl Default for Slab<f32, 1> {
    fn default() -> Self {
        Slab {
            items: take(1, addr_of_mut!(FLOATS) as *mut [f32]),
            len: 0,
        }
    }
}

impl Default for Slab<u32, 2> {
    fn default() -> Self {
        Slab {
            items: take(2, addr_of_mut!(INDICES) as *mut [u32]),
            len: 0,
        }
    }
}

impl<T: Copy, const POOL: usize> Pool<T> for Slab<T, POOL> {
    fn clear(&mut self) {
        self.len = 0;
    }
    fn push(&mut self, v: T) -> bool {
        match self.items.get_mut(self.len) {
            Some(slot) => {
                *slot = v;
                self.len += 1;
                true
            }
            None => false,
        }
    }
    fn as_slice(&self) -> &[T] {
        self.items.get(..self.len).unwrap_or(&[])
    }
    fn as_mut_slice(&mut self) -> &mut [T] {
        self.items.get_mut(..self.len).unwrap_or(&mut [])
    }
}
