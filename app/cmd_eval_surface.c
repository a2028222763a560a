/* Placeholder until its module lands (this session). */
#include "app.h"
int cmd_eval_surface(int argc, char **argv)
{
    (void)argc;
    (void)argv;
    return app_fail("eval-surface", bf_fail(BF_UNSUPPORTED, "eval-surface is not built yet"));
}
