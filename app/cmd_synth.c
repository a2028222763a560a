/* Placeholder until its module lands (this session). */
#include "app.h"
int cmd_synth(int argc, char **argv)
{
    (void)argc;
    (void)argv;
    return app_fail("synth", bf_fail(BF_UNSUPPORTED, "synth is not built yet"));
}
