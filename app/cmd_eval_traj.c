/* Placeholder until its module lands (this session). */
#include "app.h"
int cmd_eval_traj(int argc, char **argv)
{
    (void)argc;
    (void)argv;
    return app_fail("eval-traj", bf_fail(BF_UNSUPPORTED, "eval-traj is not built yet"));
}
