//! The compositor: a look relights the scene's basis images (the paper's 5.1), on the CPU,
//! fast enough that a whole gallery renders while a designer waits.
//!
//! - [`basis`]: the per-light HDR images, loaded once in the layout the kernels stream;
//! - [`render`]: the kernels (AVX-512 where the CPU has it, a portable path elsewhere);
//! - [`color`]: CIELAB and the fast sRGB encoders the thumbnails and the gallery use;
//! - [`cpu`]: the tokens that prove a CPU feature, without which no SIMD kernel is reached.
//!
//! Pure computation: no transport, no files but the basis images it is asked to read.

pub mod basis;
pub mod color;
pub mod cpu;
pub mod render;
