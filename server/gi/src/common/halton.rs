//! The Halton sequence, kept in the scene crate (`lightcast_scene::halton`) so that the scene's
//! own samplers (`scene::emitters`) share it with the methods'.

pub use crate::scene::halton::halton;
