/* placeholder */ typedef int bf_eval_placeholder;
