// Test probe: one loop of a requested length, checked afterwards for having ended for its own reason,
// the way lib/bvh.glsl checks its traversal loop. On lavapipe a loop past the per-invocation budget
// (~65 535 iterations, PLATFORM.md §6.1) is cut short silently; the check must raise STATUS_LOOP_BUDGET.
#version 460
#extension GL_EXT_scalar_block_layout : require
#include "lib/abi.glsl"

layout(local_size_x = WORKGROUP_SIZE) in;
#define LOOP_CAP 0xFFFFFFFFu
// Output, 2 words per invocation: iterations run, final xorshift32 state.
layout(set = 0, binding = BINDING_PROBE_OUT, scalar) writeonly buffer ProbeOut { uint probe_out[]; };
PUSH_LoopBudgetPush;

void main() {
    uint i = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * WORKGROUP_SIZE + gl_GlobalInvocationID.x;
    if (i >= invocation_count) return;
    // xorshift32 (Marsaglia 2003): a nonlinear recurrence with no closed form, and the trip count is
    // a push constant, so the compiler can neither fold nor shorten the loop.
    uint x = i + 1u;
    uint k = 0u;
    // The loop ends for its own reason only at the `break`, which sets `finished`. The bound is a cap
    // the compiler can see (reached only if `iterations` is 2^32 - 1), so `finished` is not provably
    // true after the loop and the check survives optimisation. A re-test of the loop condition after
    // the loop (`for (; k < n; k++) ...; if (k < n)`) does not: it is provably false, the compiler
    // folds it, and a truncated loop goes unnoticed (measured on lavapipe).
    bool finished = false;
    for (uint step = 0u; step < LOOP_CAP; step++) {
        if (k == iterations) { finished = true; break; }
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        k++;
    }
    if (!finished) raise_status(STATUS_LOOP_BUDGET);
    probe_out[2u * i] = k;
    probe_out[2u * i + 1u] = x;
}
