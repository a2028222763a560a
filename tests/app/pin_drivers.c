/* Preloaded into the bitfuse program by test_cli in sanitizer builds: keeps
 * lavapipe and the validation layer mapped until exit (RTLD_NODELETE), as
 * tests/test_main.c does for the test binaries. The loader unloads them in
 * vkDestroyInstance, after which the caches they keep in their own globals
 * look like leaks from an unknown module; pinned, they stay reachable, and
 * what bitfuse itself leaks is still reported. */
#include <dlfcn.h>

__attribute__((constructor)) static void pin_drivers(void)
{
    dlopen("libvulkan_lvp.so", RTLD_NOW | RTLD_LOCAL | RTLD_NODELETE);
    dlopen("libVkLayer_khronos_validation.so", RTLD_NOW | RTLD_LOCAL | RTLD_NODELETE);
}
