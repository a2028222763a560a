/* Placeholder until its module lands (this session). */
#include "app.h"
int cmd_info(int argc, char **argv)
{
    (void)argc;
    (void)argv;
    return app_fail("info", bf_fail(BF_UNSUPPORTED, "info is not built yet"));
}
