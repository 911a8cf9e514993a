// umbrasweep — the occludee answers' codes shared by the device's tests (`hdm.wgsl`, which
// answers rectangle queries, and `boxes.wgsl`, which combines them into box answers): the
// `plane::Coverage` codes and the query slot with nothing to test. WGSL has no includes:
// `gpu::SHADERS` prepends this file to each of them.

const PARTIAL: u32 = 0u;
const HIDDEN: u32 = 1u;
const EMPTY: u32 = 2u;
// A query slot with nothing to test: answered `PARTIAL`.
const NO_PLANE: u32 = 0xffffffffu;
