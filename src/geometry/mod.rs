//! Primitive intersection tests shared by the native and brute-force backends.

pub mod bounds;
pub mod sphere;
pub mod triangle;

pub use bounds::Aabb;
pub use sphere::intersect_sphere;
pub use triangle::{face_normal, intersect_triangle, RayTransform};
