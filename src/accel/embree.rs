//! The Embree backend (placeholder until the Embree issue lands).

use super::{Hit, Traversal};
use crate::error::Result;
use crate::ray::Ray;
use crate::scene::Shape;

pub struct EmbreeBackend;

impl EmbreeBackend {
    pub fn build(_shapes: &[Shape], _threads: usize) -> Result<Self> {
        crate::bail!("the embree backend is not available in this build")
    }
}

impl Traversal for EmbreeBackend {
    fn name(&self) -> &'static str {
        "embree"
    }
    fn memory_bytes(&self) -> usize {
        0
    }
    fn intersect(&self, _ray: &Ray) -> Option<Hit> {
        None
    }
    fn occluded(&self, _ray: &Ray) -> bool {
        false
    }
}
