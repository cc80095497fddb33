/* IBL_INLINE, what every function of kernels/ is declared with: `inline`, and on Intel's OpenCL CPU
 * runtime (the runtime defines IBL_ALWAYS_INLINE there: iblbake/device/programs.py) always inlined.
 * That runtime (2026.2) passes a float3 argument or return value of a call it leaves out of line
 * wrongly from a vectorised kernel (work items 1-15 of each 16 get other items' components), and
 * its inliner leaves large functions called from two kernels of one program out of line
 * (material_sample: the material pass and the reference's paths, so the textured G-buffer's
 * normals were garbage in every frame with bounces). tests/test_intel_cpu.py holds the three-line
 * reproduction. Not on PoCL: inlining everything there puts every call's private arrays (the BVH
 * stacks) in each work item's context, and a 3600-item work group of the reference overflows its
 * thread's stack. */
#ifndef IBLBAKE_INLINE_H
#define IBLBAKE_INLINE_H
#ifdef IBL_ALWAYS_INLINE
#define IBL_INLINE __attribute__((always_inline)) inline
#else
#define IBL_INLINE inline
#endif
#endif
