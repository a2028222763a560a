/* Placeholder until its module lands (this session). */
#include "app.h"
int cmd_devices(int argc, char **argv)
{
    (void)argc;
    (void)argv;
    return app_fail("devices", bf_fail(BF_UNSUPPORTED, "devices is not built yet"));
}
