//! The paper's method: visual objectives from reference images, the sequential key/fill
//! sampler with its constraints, targeting of regions, and the clustered gallery, over a
//! [`stage::Stage`] (a scene with its basis images loaded).
//!
//! Pure and seeded: everything that draws takes `&mut impl Rng` and plain data, and
//! nothing here does network I/O, so a generate is reproducible from its seed.

pub mod constrain;
pub mod decode;
pub mod gallery;
pub mod objective;
pub mod preference;
pub mod sampler;
pub mod sheet;
pub mod stage;
pub mod steer;
pub mod targeting;
