// Kernel specialisation (issue "Fast kernels"): specialisation constants, FEATURES and FEATURES2, say which
// parts of the one path loop a request and its scene use. Every optional part is guarded by
// HAS(F_…); the driver folds the constant when it builds the pipeline and drops what is off, so a
// kernel pays only for what it renders. The bits are the F_* and F2_* constants of src/contract/consts.rs;
// the default (every bit set) is the general kernel that probes and tests without a plan use.
#ifndef PATHGRAD_FEATURES_GLSL
#define PATHGRAD_FEATURES_GLSL

layout(constant_id = SPEC_FEATURES) const uint FEATURES = 0xFFFFFFFFu;
// The second word, once the first was full: the F2_* bits, tested by HAS2.
layout(constant_id = SPEC_FEATURES2) const uint FEATURES2 = 0xFFFFFFFFu;

// A function, not a constant expression: glslang would turn `(FEATURES & bit) != 0u` into
// OpSpecConstantOp chains, which SPIRV-Tools 2023.1's optimiser mishandles ("ID has not been
// defined"); as ordinary instructions on the constant, the driver folds them just the same.
bool has_feature(uint bit) { return (FEATURES & bit) != 0u; }
#define HAS(bit) has_feature(uint(bit))
bool has_feature2(uint bit) { return (FEATURES2 & bit) != 0u; }
#define HAS2(bit) has_feature2(uint(bit))

#endif
