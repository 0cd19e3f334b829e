//! `Image`: RGB f32 images, EXR and PNG output, tone mapping and signed false-colour maps.
