//! # voxstream-procedural: built-in producers that need no files
//!
//! Producers sit at the far end of the loop (camera → renderer → feedback → cache manager → **producers** → pools):
//! the cache manager asks them for the nodes rays missed.
//!
//! - [`MengerSponge`] (N = 3): exact integer fractal, any depth; GigaVoxels' deep-zoom showcase.
//! - [`Hypertexture`] (N = 2): a torus amplified by 16 octaves of band-limited fBm, with an oracle for the empty
//!   outside and the solid core (GigaVoxels' hypertextured bunny, [R08] §7).
//! - [`Shell`] (N = 2): a smooth closed-form density, the reference for image tests.
//!
//! ```
//! use voxstream_core::{NodeKey, Producer};
//! use voxstream_procedural::MengerSponge;
//! let sponge = MengerSponge::default();
//! // The centre child of the root is one of the sponge's holes: the oracle knows without producing it.
//! assert_eq!(sponge.oracle(NodeKey::ROOT.child(13, 3)), Some(0.0));
//! ```

pub mod brick_fill;
pub mod hypertexture;
/// The noise moved to `voxstream-core` (the meshes use it too); re-exported where it was.
pub use voxstream_core::noise;
pub mod shell;
pub mod sponge;

pub use hypertexture::Hypertexture;
pub use shell::Shell;
pub use sponge::MengerSponge;
