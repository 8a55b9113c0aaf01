//! Strain fields: what drives the microstructure; and the element stress
//! that comes with a strain.
//!
//! * [`element`]: per-tet deformation gradient, principal stretches and
//!   directions, Biot and Green strains, volume ratio;
//! * [`stress`]: per-tet Cauchy stress, von Mises stress and strain energy
//!   density of the corotational material;
//! * [`surface`]: the 2×2 deformation `T` of the top surface in texture
//!   space (Nagano et al. 2015 eq. 10), per triangle and per vertex, evaluated at any
//!   UV point through the closed-form SVD (eq. 11–13);
//! * [`svd2`]: the closed-form 2×2 SVD (the GPU stage runs the same formulas);
//! * [`raster`]: the CPU reference raster of the field into a UV grid;
//! * [`volume`]: each region's volume change and most compressed tets.
//!
//! No I/O here: the exporters, a layer above, write images and VTU fields.

pub mod element;
pub mod raster;
pub mod stress;
pub mod surface;
pub mod svd2;
pub mod volume;

pub use element::{ElementStrains, PrincipalStrain};
pub use raster::StrainRaster;
pub use stress::{element_stresses, TetStress};
pub use surface::{SurfaceField, SurfaceStrain, VertexStrain};
pub use svd2::Svd2;
pub use volume::{region_volumes, RegionVolume};
