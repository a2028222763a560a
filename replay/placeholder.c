/* placeholder */ typedef int bf_replay_placeholder;
