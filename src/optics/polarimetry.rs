//! Polarimetric quantities derived from Stokes vectors and Mueller matrices.
