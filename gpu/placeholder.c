/* placeholder */ typedef int bf_gpu_placeholder;
