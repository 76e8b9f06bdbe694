# One image for the API and the workers; docker-compose.yml picks the command.

# The web page (web/): built with node, only its static files go into the image.
FROM node:20-slim AS web
WORKDIR /src/web
COPY web/package.json web/package-lock.json ./
RUN npm ci --no-audit --no-fund
COPY web ./
RUN npm run build  # writes /src/services/api/static

FROM python:3.11-slim
ENV PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 PIP_NO_CACHE_DIR=1
WORKDIR /app
# The locked, hash-checked releases the tests ran (scripts/lock makes locks/service.txt), then the
# project without dependencies: every one is in the lock.
# The lock holds the extra cad too (OpenCascade's OCP, for the step format).
COPY locks/service.txt ./locks/
RUN pip install --require-hashes -r locks/service.txt
COPY pyproject.toml README.md ./
COPY shared ./shared
COPY services ./services
COPY --from=web /src/services/api/static ./services/api/static
RUN pip install --no-deps . && useradd --create-home --uid 10001 prism
USER prism
EXPOSE 8000
CMD ["uvicorn", "prism_api.main:app", "--host", "0.0.0.0", "--port", "8000"]
