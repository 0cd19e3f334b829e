// Specialises a SPIR-V kernel to values of its specialisation constants and optimises what is left,
// through Debian's SPIRV-Tools (spirv-tools, static libraries): the driver then parses and
// optimises only the code the value keeps. Called from src/gpu/specialise.rs.
#include <spirv-tools/libspirv.hpp>
#include <spirv-tools/optimizer.hpp>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <unordered_map>
#include <vector>

// `n` constants: `spec_ids[i]` takes `values[i]` (an id the module lacks is ignored).
extern "C" int pathgrad_specialise_spirv(const uint32_t* words, size_t count, const uint32_t* spec_ids,
                                         const uint32_t* values, size_t n, uint32_t** out, size_t* out_count) {
    try {
        spvtools::Optimizer optimizer(SPV_ENV_VULKAN_1_2);
        optimizer.SetMessageConsumer([](spv_message_level_t, const char*, const spv_position_t&, const char*) {});
        std::unordered_map<uint32_t, std::vector<uint32_t>> defaults;
        for (size_t i = 0; i < n; ++i) defaults[spec_ids[i]] = {values[i]};
        optimizer.RegisterPass(spvtools::CreateStripDebugInfoPass());
        optimizer.RegisterPass(spvtools::CreateSetSpecConstantDefaultValuePass(defaults));
        optimizer.RegisterPass(spvtools::CreateFreezeSpecConstantValuePass());
        // First what the value switches off is cut away — its tests folded, their dead branches and
        // code removed — so the pipeline below works on a module a fifth the size: on the adjoint
        // kernel the result is the same words in about half the time (BENCHMARKS.md).
        optimizer.RegisterPass(spvtools::CreateCCPPass());
        optimizer.RegisterPass(spvtools::CreateDeadBranchElimPass());
        optimizer.RegisterPass(spvtools::CreateAggressiveDCEPass());
        // The whole performance pipeline again: with the features frozen it simplifies across what
        // is left. Primal renders were faster in two interleaved sets than after only constant
        // propagation and dead-code elimination (BENCHMARKS.md).
        optimizer.RegisterPerformancePasses();
        // Ids renumbered from 1: the passes keep the whole kernel's ids (a bound of ~1.8 M for
        // ~5 000 instructions), and lavapipe's SPIR-V reader allocates a value per id up to the
        // bound, 144 bytes each (260 MB for the sphere's primal kernel; BENCHMARKS.md, issue 38).
        optimizer.RegisterPass(spvtools::CreateCompactIdsPass());
        spvtools::OptimizerOptions options;
        options.set_run_validator(false);  // build.rs's modules are valid; the driver checks again
        std::vector<uint32_t> result;
        if (!optimizer.Run(words, count, &result, options)) return 1;
        uint32_t* copy = static_cast<uint32_t*>(std::malloc(result.size() * sizeof(uint32_t)));
        if (copy == nullptr) return 2;
        std::memcpy(copy, result.data(), result.size() * sizeof(uint32_t));
        *out = copy;
        *out_count = result.size();
        return 0;
    } catch (...) {
        return 3;
    }
}

extern "C" void pathgrad_free_spirv(uint32_t* words) { std::free(words); }

// The optimizer's version, for the cache key: another SPIRV-Tools may optimise differently.
extern "C" const char* pathgrad_spirv_tools_version() { return spvSoftwareVersionDetailsString(); }
