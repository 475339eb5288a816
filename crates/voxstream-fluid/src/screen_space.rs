//! Screen-space smoothing of the fluid's depth image (Reichl §6.5.3).
