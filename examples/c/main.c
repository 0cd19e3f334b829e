/* An engine in C embeds pathgrad through its C API (capi/include/pathgrad.h): it creates its own
 * Vulkan instance and device with the validation layer on and a messenger that counts messages,
 * lends them to pathgrad, records a render and a backward pass into its own command buffers,
 * copies pathgrad's image and gradient buffers out itself, checks them against pathgrad's CPU
 * reference and its own read-back calls, and goes on using its device after pathgrad is gone.
 * Exits non-zero on any error or validation message.
 *
 *   cargo test --manifest-path capi/Cargo.toml --test c_example   (compiles and runs this file)
 *
 * C11; link libpathgrad_c.a -lvulkan -lstdc++ -lgcc_s -lm -lpthread -ldl (capi/README.md). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <vulkan/vulkan.h>

#include "pathgrad.h"

enum { WIDTH = 32, HEIGHT = 32, SPP = 4 };
static const char *PARAM = "white.reflectance.value";

static unsigned long validation_messages = 0;

static VKAPI_ATTR VkBool32 VKAPI_CALL count_message(VkDebugUtilsMessageSeverityFlagBitsEXT severity,
                                                    VkDebugUtilsMessageTypeFlagsEXT types,
                                                    const VkDebugUtilsMessengerCallbackDataEXT *data, void *user) {
  (void)severity;
  (void)types;
  (void)user;
  validation_messages++;
  fprintf(stderr, "host validation: %s\n", data && data->pMessage ? data->pMessage : "(no message)");
  return VK_FALSE;
}

/* A Vulkan call of the host's own that must succeed. */
#define VK_CHECK(call)                                                                                                 \
  do {                                                                                                                 \
    VkResult r_ = (call);                                                                                              \
    if (r_ != VK_SUCCESS) {                                                                                            \
      fprintf(stderr, "%s:%d: %s returned %d\n", __FILE__, __LINE__, #call, (int)r_);                                  \
      exit(1);                                                                                                         \
    }                                                                                                                  \
  } while (0)

/* A pathgrad call that must succeed. */
#define PG_CHECK(call)                                                                                                 \
  do {                                                                                                                 \
    PgStatus s_ = (call);                                                                                              \
    if (s_ != PG_STATUS_OK) {                                                                                          \
      fprintf(stderr, "%s:%d: status %d: %s\n", __FILE__, __LINE__, (int)s_, pg_last_error_message());                 \
      exit(1);                                                                                                         \
    }                                                                                                                  \
  } while (0)

typedef struct Host {
  VkInstance instance;
  VkDebugUtilsMessengerEXT messenger;
  VkPhysicalDevice physical_device;
  VkDevice device;
  uint32_t queue_family;
  VkQueue queue;
  VkCommandPool pool;
} Host;

/* A host-visible buffer of the host's own, for copies to and from pathgrad's buffers. */
typedef struct Staging {
  VkBuffer buffer;
  VkDeviceMemory memory;
  VkDeviceSize size;
} Staging;

static Staging staging_new(const Host *h, VkDeviceSize size) {
  Staging s = {.size = size};
  VkBufferCreateInfo info = {.sType = VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO,
                             .size = size,
                             .usage = VK_BUFFER_USAGE_TRANSFER_SRC_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT};
  VK_CHECK(vkCreateBuffer(h->device, &info, NULL, &s.buffer));
  VkMemoryRequirements needs;
  vkGetBufferMemoryRequirements(h->device, s.buffer, &needs);
  VkPhysicalDeviceMemoryProperties kinds;
  vkGetPhysicalDeviceMemoryProperties(h->physical_device, &kinds);
  VkMemoryPropertyFlags wanted = VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT;
  uint32_t kind = UINT32_MAX;
  for (uint32_t i = 0; i < kinds.memoryTypeCount && kind == UINT32_MAX; i++) {
    if ((needs.memoryTypeBits & (1u << i)) && (kinds.memoryTypes[i].propertyFlags & wanted) == wanted) kind = i;
  }
  if (kind == UINT32_MAX) {
    fprintf(stderr, "no host-visible memory\n");
    exit(1);
  }
  VkMemoryAllocateInfo alloc = {
      .sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO, .allocationSize = needs.size, .memoryTypeIndex = kind};
  VK_CHECK(vkAllocateMemory(h->device, &alloc, NULL, &s.memory));
  VK_CHECK(vkBindBufferMemory(h->device, s.buffer, s.memory, 0));
  return s;
}

static void staging_free(const Host *h, Staging *s) {
  vkDestroyBuffer(h->device, s->buffer, NULL);
  vkFreeMemory(h->device, s->memory, NULL);
}

static void *staging_map(const Host *h, const Staging *s) {
  void *p = NULL;
  VK_CHECK(vkMapMemory(h->device, s->memory, 0, s->size, 0, &p));
  return p;
}

static VkCommandBuffer begin(const Host *h) {
  VkCommandBufferAllocateInfo alloc = {.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO,
                                       .commandPool = h->pool,
                                       .level = VK_COMMAND_BUFFER_LEVEL_PRIMARY,
                                       .commandBufferCount = 1};
  VkCommandBuffer cmd;
  VK_CHECK(vkAllocateCommandBuffers(h->device, &alloc, &cmd));
  VkCommandBufferBeginInfo info = {.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO,
                                   .flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT};
  VK_CHECK(vkBeginCommandBuffer(cmd, &info));
  return cmd;
}

/* Ends, submits and waits: how this engine runs a frame. */
static void submit_and_wait(const Host *h, VkCommandBuffer cmd) {
  VK_CHECK(vkEndCommandBuffer(cmd));
  VkFenceCreateInfo fence_info = {.sType = VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
  VkFence fence;
  VK_CHECK(vkCreateFence(h->device, &fence_info, NULL, &fence));
  VkSubmitInfo submit = {.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO, .commandBufferCount = 1, .pCommandBuffers = &cmd};
  VK_CHECK(vkQueueSubmit(h->queue, 1, &submit, fence));
  VK_CHECK(vkWaitForFences(h->device, 1, &fence, VK_TRUE, UINT64_MAX));
  vkDestroyFence(h->device, fence, NULL);
  vkFreeCommandBuffers(h->device, h->pool, 1, &cmd);
}

static void copy(VkCommandBuffer cmd, VkBuffer from, VkDeviceSize from_offset, VkBuffer to, VkDeviceSize to_offset,
                 VkDeviceSize size) {
  VkBufferCopy region = {.srcOffset = from_offset, .dstOffset = to_offset, .size = size};
  vkCmdCopyBuffer(cmd, from, to, 1, &region);
}

/* Makes transfer writes visible to the host. */
static void host_barrier(VkCommandBuffer cmd) {
  VkMemoryBarrier b = {.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER,
                       .srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT,
                       .dstAccessMask = VK_ACCESS_HOST_READ_BIT};
  vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 1, &b, 0, NULL, 0, NULL);
}

/* The engine's instance (Vulkan 1.2, validation on) and device, with what pathgrad needs enabled;
 * `create_info` is left filled in, with `features2` and the structs it chains, for pathgrad. */
typedef struct DeviceSetup {
  VkPhysicalDeviceShaderAtomicFloatFeaturesEXT atomic_float;
  VkPhysicalDeviceVulkan12Features vulkan12;
  VkPhysicalDeviceFeatures2 features2;
  const char *extensions[8];
  float priority;
  VkDeviceQueueCreateInfo queue;
  VkDeviceCreateInfo create_info;
} DeviceSetup;

static void host_new(Host *h, DeviceSetup *d) {
  const char *layers[] = {"VK_LAYER_KHRONOS_validation"};
  const char *instance_extensions[] = {VK_EXT_DEBUG_UTILS_EXTENSION_NAME};
  VkApplicationInfo app = {.sType = VK_STRUCTURE_TYPE_APPLICATION_INFO,
                           .pApplicationName = "pathgrad C example",
                           .apiVersion = VK_API_VERSION_1_2};
  VkInstanceCreateInfo instance_info = {.sType = VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO,
                                        .pApplicationInfo = &app,
                                        .enabledLayerCount = 1,
                                        .ppEnabledLayerNames = layers,
                                        .enabledExtensionCount = 1,
                                        .ppEnabledExtensionNames = instance_extensions};
  VK_CHECK(vkCreateInstance(&instance_info, NULL, &h->instance));
  VkDebugUtilsMessengerCreateInfoEXT messenger_info = {
      .sType = VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT,
      .messageSeverity = VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT,
      .messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT,
      .pfnUserCallback = count_message};
  PFN_vkCreateDebugUtilsMessengerEXT create_messenger =
      (PFN_vkCreateDebugUtilsMessengerEXT)vkGetInstanceProcAddr(h->instance, "vkCreateDebugUtilsMessengerEXT");
  if (!create_messenger) {
    fprintf(stderr, "no VK_EXT_debug_utils\n");
    exit(1);
  }
  VK_CHECK(create_messenger(h->instance, &messenger_info, NULL, &h->messenger));

  /* A CPU implementation first (as tests want; an engine would pick its GPU). */
  uint32_t count = 8;
  VkPhysicalDevice devices[8];
  VkResult listed = vkEnumeratePhysicalDevices(h->instance, &count, devices);
  if ((listed != VK_SUCCESS && listed != VK_INCOMPLETE) || count == 0) {
    fprintf(stderr, "no physical device\n");
    exit(1);
  }
  h->physical_device = devices[0];
  for (uint32_t i = 0; i < count; i++) {
    VkPhysicalDeviceProperties p;
    vkGetPhysicalDeviceProperties(devices[i], &p);
    if (p.deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU) {
      h->physical_device = devices[i];
      break;
    }
  }
  uint32_t families = 16;
  VkQueueFamilyProperties family[16];
  vkGetPhysicalDeviceQueueFamilyProperties(h->physical_device, &families, family);
  h->queue_family = UINT32_MAX;
  for (uint32_t i = 0; i < families && h->queue_family == UINT32_MAX; i++) {
    if (family[i].queueFlags & VK_QUEUE_COMPUTE_BIT) h->queue_family = i;
  }
  if (h->queue_family == UINT32_MAX) {
    fprintf(stderr, "no compute queue\n");
    exit(1);
  }

  /* What pathgrad needs (capi/README.md), merged into what the engine wants (here: nothing else). */
  memset(d, 0, sizeof *d);
  d->atomic_float.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_SHADER_ATOMIC_FLOAT_FEATURES_EXT;
  d->atomic_float.shaderBufferFloat32AtomicAdd = VK_TRUE;
  d->vulkan12.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_2_FEATURES;
  d->vulkan12.pNext = &d->atomic_float;
  d->vulkan12.scalarBlockLayout = VK_TRUE;
  d->vulkan12.bufferDeviceAddress = VK_TRUE;
  d->features2.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_FEATURES_2;
  d->features2.pNext = &d->vulkan12;
  d->features2.features.shaderInt64 = VK_TRUE;
  size_t extensions = pg_required_device_extension_count();
  if (extensions > 8) extensions = 8;
  for (size_t i = 0; i < extensions; i++) d->extensions[i] = pg_required_device_extension(i);
  d->priority = 1.0f;
  d->queue = (VkDeviceQueueCreateInfo){.sType = VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO,
                                       .queueFamilyIndex = h->queue_family,
                                       .queueCount = 1,
                                       .pQueuePriorities = &d->priority};
  d->create_info = (VkDeviceCreateInfo){.sType = VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO,
                                        .pNext = &d->features2,
                                        .queueCreateInfoCount = 1,
                                        .pQueueCreateInfos = &d->queue,
                                        .enabledExtensionCount = (uint32_t)extensions,
                                        .ppEnabledExtensionNames = d->extensions};
  VK_CHECK(vkCreateDevice(h->physical_device, &d->create_info, NULL, &h->device));
  vkGetDeviceQueue(h->device, h->queue_family, 0, &h->queue);
  VkCommandPoolCreateInfo pool_info = {.sType = VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO,
                                       .queueFamilyIndex = h->queue_family};
  VK_CHECK(vkCreateCommandPool(h->device, &pool_info, NULL, &h->pool));
}

static void host_close(Host *h) {
  vkDeviceWaitIdle(h->device);
  vkDestroyCommandPool(h->device, h->pool, NULL);
  vkDestroyDevice(h->device, NULL);
  PFN_vkDestroyDebugUtilsMessengerEXT destroy_messenger =
      (PFN_vkDestroyDebugUtilsMessengerEXT)vkGetInstanceProcAddr(h->instance, "vkDestroyDebugUtilsMessengerEXT");
  destroy_messenger(h->instance, h->messenger, NULL);
  vkDestroyInstance(h->instance, NULL);
}

static int fail(const char *what) {
  fprintf(stderr, "FAILED: %s\n", what);
  return 1;
}

int main(void) {
  Host host;
  DeviceSetup setup;
  host_new(&host, &setup);

  PgVulkanDevice lent = {.get_instance_proc_addr = vkGetInstanceProcAddr,
                         .instance = host.instance,
                         .physical_device = host.physical_device,
                         .device = host.device,
                         .queue_family = host.queue_family,
                         .queue_index = 0,
                         .api_version = VK_API_VERSION_1_2,
                         .device_create_info = &setup.create_info};
  PgContext *ctx = NULL;
  /* A device created without what pathgrad needs is refused, naming each thing missing. */
  VkDeviceCreateInfo bare = setup.create_info;
  bare.pNext = NULL;
  bare.enabledExtensionCount = 0;
  PgVulkanDevice without = lent;
  without.device_create_info = &bare;
  if (pg_context_from_vulkan(&without, &ctx) != PG_STATUS_NOT_ENABLED || ctx != NULL)
    return fail("a device without pathgrad's features is refused");
  printf("refused: %s\n", pg_last_error_message());
  if (!strstr(pg_last_error_message(), "pg_required_device_extension"))
    return fail("the refusal names this API's list of what to enable, not a Rust name");
  PG_CHECK(pg_context_from_vulkan(&lent, &ctx));
  printf("pathgrad %s on the host's device: %s\n", pg_version(), pg_context_device_name(ctx));

  PgScene *scene = NULL;
  PG_CHECK(pg_scene_load("builtin:cornell-box", NULL, NULL, 0, &scene));
  PgParamInfo param;
  PG_CHECK(pg_scene_param_info(scene, PARAM, &param));

  /* Errors come back as codes with messages, not crashes. */
  float two[2];
  if (pg_scene_get_param(scene, PARAM, two, 2) != PG_STATUS_INVALID_ARGUMENT) return fail("a wrong count is refused");
  printf("a wrong count: %s\n", pg_last_error_message());
  if (pg_scene_param_info(scene, NULL, &param) != PG_STATUS_NULL_POINTER) return fail("a null name is refused");
  if (pg_scene_param_info(scene, "no.such.parameter", &param) != PG_STATUS_INVALID_ARGUMENT)
    return fail("an unknown name is refused");
  PG_CHECK(pg_scene_param_info(scene, PARAM, &param));

  PgRenderer *renderer = NULL;
  PG_CHECK(pg_renderer_create(ctx, scene, &renderer));
  PgFrameDesc desc = {.width = WIDTH, .height = HEIGHT, .spp = SPP, .seed = 7};
  PgFrame *frame = NULL;
  PG_CHECK(pg_frame_create(renderer, &desc, &frame)); /* builds the kernels now */
  PgBufferView image, adjoint, gradient;
  PG_CHECK(pg_frame_buffer(frame, PG_BUFFER_IMAGE, &image));
  PG_CHECK(pg_frame_buffer(frame, PG_BUFFER_ADJOINT, &adjoint));
  PG_CHECK(pg_frame_buffer(frame, PG_BUFFER_GRADIENT, &gradient));
  if (image.layout != PG_LAYOUT_RGB_SUMS || gradient.layout != PG_LAYOUT_GRADIENT_F32) return fail("layouts");
  const size_t n = (size_t)WIDTH * HEIGHT * 3;
  const size_t values = pg_scene_value_count(scene);
  if (image.size < n * sizeof(float) || gradient.size < values * sizeof(float)) return fail("buffer sizes");

  /* Frame 1: clear and render into the host's command buffer; the host copies the image out. */
  Staging out = staging_new(&host, image.size);
  VkCommandBuffer cmd = begin(&host);
  PG_CHECK(pg_frame_record_clear(frame, cmd));
  PG_CHECK(pg_frame_record_render(frame, cmd, 0, SPP));
  copy(cmd, image.buffer, image.offset, out.buffer, 0, image.size);
  host_barrier(cmd);
  submit_and_wait(&host, cmd);
  float *sums = staging_map(&host, &out);
  double mean = 0.0;
  int finite = 1;
  for (size_t i = 0; i < n; i++) {
    finite &= isfinite(sums[i]);
    mean += sums[i] / SPP;
  }
  mean /= (double)n;
  vkUnmapMemory(host.device, out.memory);
  staging_free(&host, &out);

  /* The same image through pathgrad's read-back call, and on its CPU reference. */
  float *rgb = malloc(n * sizeof(float));
  float *cpu = malloc(n * sizeof(float));
  PG_CHECK(pg_frame_read_image(frame, SPP, rgb, n));
  PG_CHECK(pg_scene_render_cpu(scene, &desc, cpu, n));
  double read_mean = 0.0, cpu_mean = 0.0;
  for (size_t i = 0; i < n; i++) {
    read_mean += rgb[i];
    cpu_mean += cpu[i];
  }
  read_mean /= (double)n;
  cpu_mean /= (double)n;
  printf("rendered %dx%d at %d spp: mean %.5f (read back %.5f, CPU reference %.5f)\n", WIDTH, HEIGHT, SPP, mean,
         read_mean, cpu_mean);
  if (!finite || !(mean > 0.01)) return fail("a lit, finite image");
  if (!(fabs(mean - read_mean) <= 1e-6 * mean)) return fail("the host's copy and pathgrad's read-back agree");
  if (!(fabs(mean - cpu_mean) <= 1e-3 * cpu_mean)) return fail("the device and the CPU reference agree");

  /* Frame 2: loss = mean of the image, so the adjoint image is 1/n everywhere. The host writes it
   * into pathgrad's adjoint buffer and reads the gradient buffer, in the same command buffer as
   * the backward pass (pathgrad's recorded commands bring their own barriers). */
  Staging in = staging_new(&host, adjoint.size);
  float *a = staging_map(&host, &in);
  for (size_t i = 0; i < n; i++) a[i] = 1.0f / (float)n;
  vkUnmapMemory(host.device, in.memory);
  Staging grads = staging_new(&host, gradient.size);
  cmd = begin(&host);
  copy(cmd, in.buffer, 0, adjoint.buffer, adjoint.offset, n * sizeof(float));
  PG_CHECK(pg_frame_record_backward(frame, cmd, 0, SPP / 2));
  PG_CHECK(pg_frame_record_backward(frame, cmd, SPP / 2, SPP));
  copy(cmd, gradient.buffer, gradient.offset, grads.buffer, 0, gradient.size);
  host_barrier(cmd);
  submit_and_wait(&host, cmd);
  PG_CHECK(pg_frame_check_status(frame));
  float *g = staging_map(&host, &grads);
  float *read = malloc(values * sizeof(float));
  PG_CHECK(pg_frame_read_gradients(frame, read, values));
  double dwhite = 0.0;
  int same = 1;
  for (size_t i = 0; i < values; i++) {
    finite &= isfinite(g[i]);
    same &= g[i] == read[i];
  }
  for (size_t i = 0; i < param.count; i++) dwhite += g[param.offset + i];
  vkUnmapMemory(host.device, grads.memory);
  staging_free(&host, &grads);
  staging_free(&host, &in);
  printf("d mean / d %s (summed over RGB) = %.5f\n", PARAM, dwhite);
  if (!finite || !same) return fail("finite gradients, equal to pathgrad's read-back");
  /* Brighter white walls make a brighter image. */
  if (!(dwhite > 0.0)) return fail("the gradient of the white walls' reflectance is positive");

  /* Parameters by name on the renderer (uploaded on the host's queue; nothing is in flight). */
  float white[3] = {0.5f, 0.5f, 0.5f}, back[3];
  PG_CHECK(pg_renderer_set_param(renderer, PARAM, white, 3));
  PG_CHECK(pg_renderer_get_param(renderer, PARAM, back, 3));
  if (back[0] != 0.5f || back[2] != 0.5f) return fail("a parameter set on the renderer reads back");

  free(rgb);
  free(cpu);
  free(read);
  /* Any order: a frame keeps its renderer, and both their context, alive. */
  pg_renderer_destroy(renderer);
  pg_context_destroy(ctx);
  pg_scene_destroy(scene);
  pg_frame_destroy(frame);

  /* pathgrad is gone; the engine's device goes on working. */
  Staging own = staging_new(&host, 1024);
  cmd = begin(&host);
  vkCmdFillBuffer(cmd, own.buffer, 0, 1024, 0x5EED);
  host_barrier(cmd);
  submit_and_wait(&host, cmd);
  uint32_t *words = staging_map(&host, &own);
  int filled = words[0] == 0x5EED && words[255] == 0x5EED;
  vkUnmapMemory(host.device, own.memory);
  staging_free(&host, &own);
  host_close(&host);
  printf("the host's device still works: %s; validation messages: %lu\n", filled ? "yes" : "no", validation_messages);
  if (!filled) return fail("the host's own work after pathgrad");
  return validation_messages == 0 ? 0 : fail("the validation layer reported messages");
}
