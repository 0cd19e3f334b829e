pub mod embree;
