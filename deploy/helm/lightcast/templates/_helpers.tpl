{{- define "lightcast.name" -}}
{{- default .Chart.Name .Values.nameOverride | trunc 63 | trimSuffix "-" }}
{{- end }}

{{- define "lightcast.fullname" -}}
{{- if .Values.fullnameOverride }}
{{- .Values.fullnameOverride | trunc 63 | trimSuffix "-" }}
{{- else }}
{{- $name := default .Chart.Name .Values.nameOverride }}
{{- if contains $name .Release.Name }}
{{- .Release.Name | trunc 63 | trimSuffix "-" }}
{{- else }}
{{- printf "%s-%s" .Release.Name $name | trunc 63 | trimSuffix "-" }}
{{- end }}
{{- end }}
{{- end }}

{{- define "lightcast.selectorLabels" -}}
app.kubernetes.io/name: {{ include "lightcast.name" . }}
app.kubernetes.io/instance: {{ .Release.Name }}
{{- end }}

{{- define "lightcast.labels" -}}
helm.sh/chart: {{ printf "%s-%s" .Chart.Name .Chart.Version | replace "+" "_" | trunc 63 | trimSuffix "-" }}
{{ include "lightcast.selectorLabels" . }}
app.kubernetes.io/version: {{ .Chart.AppVersion | quote }}
app.kubernetes.io/managed-by: {{ .Release.Service }}
{{- end }}

{{/* The Secret the tokens file comes from. */}}
{{- define "lightcast.tokensSecret" -}}
{{- default (printf "%s-tokens" (include "lightcast.fullname" .)) .Values.auth.existingSecret }}
{{- end }}

{{/* The container listens here (LIGHTCAST_LISTEN); probes and Services use the name `http`. */}}
{{- define "lightcast.containerPort" -}}
8080
{{- end }}

{{/* The Secret the routing key comes from. */}}
{{- define "lightcast.routingSecret" -}}
{{- default (printf "%s-routing" (include "lightcast.fullname" .)) .Values.routing.existingSecret }}
{{- end }}
