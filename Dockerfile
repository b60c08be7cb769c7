# thermcap: one image for the recorder, the archiver worker and the API.
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 PIP_NO_CACHE_DIR=1 THERMCAP_ROOT=/data \
    NUMBA_CACHE_DIR=/opt/thermcap/numba
WORKDIR /app
COPY pyproject.toml README.md ./
COPY recorder ./recorder
COPY archive ./archive
COPY api ./api
COPY thermcap ./thermcap
RUN pip install ".[scale,sync,report,geo]" && useradd --system --uid 10001 --home /data thermcap && mkdir -p /data && chown thermcap /data
# tpred's, TIFF-LZW's and the detector's compiled kernels, compiled here rather than by every
# container's first archive (3-10 s of a core); numba recompiles on its own on another CPU kind
RUN python -m thermcap.kernels && chown -R thermcap /opt/thermcap/numba
USER thermcap
VOLUME ["/data"]
EXPOSE 8000
HEALTHCHECK --interval=15s --timeout=5s --retries=5 CMD python -c "import urllib.request,sys; urllib.request.urlopen('http://127.0.0.1:8000/healthz', timeout=4)" || exit 1
ENTRYPOINT ["thermcap"]
CMD ["serve", "--host", "0.0.0.0", "--port", "8000"]
