# Trainer image: Debian bookworm + the JAX virtualenv, set up exactly as `make setup-trainer`.
# Build from the repository root:  docker build -f docker/trainer.Dockerfile -t liverfem-trainer .
# Train:  docker run --rm -v $PWD/runs:/opt/liverfem/runs liverfem-trainer \
#           .venv-train/bin/python -m surrogate train --data runs/data/scene1 --run runs/train/s1
FROM debian:bookworm
ENV DEBIAN_FRONTEND=noninteractive
WORKDIR /opt/liverfem
# The package list is shared with the Makefile: requirements/debian-packages-trainer.txt.
COPY requirements/debian-packages-trainer.txt requirements/
COPY scripts/setup_system.sh scripts/
RUN bash scripts/setup_system.sh requirements/debian-packages-trainer.txt \
    && rm -rf /var/lib/apt/lists/*
COPY . .
RUN make setup-trainer
CMD ["bash"]
