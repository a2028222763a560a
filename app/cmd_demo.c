/* Placeholder until its module lands (this session). */
#include "app.h"
int cmd_demo(int argc, char **argv)
{
    (void)argc;
    (void)argv;
    return app_fail("demo", bf_fail(BF_UNSUPPORTED, "demo is not built yet"));
}
